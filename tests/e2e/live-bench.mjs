// Glass-to-skeleton latency in the browser (relay timestamp of the drawn frame → drawn) at
// each lookahead, and what the worker takes per live frame: the page in Live mode, fed by
// `egoexo live replay --loop` of the sample (a wearer with wrists, two observers).
// Usage: node tests/e2e/live-bench.mjs [seconds per lookahead]  (EGOEXO_E2E_URL, EGOEXO_BIN)
// Prints `LIVEBENCH {json}`: per lookahead the latency p50/p95 (ms), the goal
// (p95 ≤ 100 ms + L/30 s), the part of it before the page draws (arrival) and before the
// worker posts the frame (posted), the worker's median ms per frame and the frames shown.

import { spawn } from 'node:child_process';

import { APP_URL, launch, openApp } from './browser.mjs';

const SECONDS = Number(process.argv[2] ?? 8);
const LOOKAHEADS = [0, 4, 8, 16];
const SAMPLE = new URL('../../public/samples/cmu-14_20.egoexo', import.meta.url).pathname;

const median = (values) => {
  const sorted = [...values].sort((a, b) => a - b);
  return sorted.length ? sorted[Math.floor((sorted.length - 1) / 2)] : null;
};
const percentile = (values, q) => {
  const sorted = [...values].sort((a, b) => a - b);
  return sorted.length ? sorted[Math.min(sorted.length - 1, Math.round((sorted.length - 1) * q))] : null;
};

const browser = await launch();
let replay;
try {
  const app = await openApp(browser, '?backend=webgl2');
  await app.waitState('idle');
  await app.page.getByRole('button', { name: 'Go live' }).click();
  await app.page.waitForSelector('#live-room[data-code]');
  const code = await app.page.getAttribute('#live-room', 'data-code');
  replay = spawn(process.env.EGOEXO_BIN ?? 'egoexo', ['live', 'replay', SAMPLE, '--url', APP_URL, '--room', code, '--loop'], {
    stdio: ['ignore', 'ignore', 'inherit'],
  });
  await app.page.waitForFunction(() => window.egoexo.live.frames > 30, null, { timeout: 120_000 });
  const rows = [];
  for (const lookahead of LOOKAHEADS) {
    await app.page.selectOption('#live-lookahead', String(lookahead));
    await app.page.waitForTimeout(1500);
    const before = await app.page.evaluate(() => {
      window.egoexo.live.resetMeasurements();
      const l = window.egoexo.live.snapshot();
      return { frames: l.frames, skipped: l.take?.skipped ?? 0 };
    });
    await app.page.waitForTimeout(SECONDS * 1000);
    const after = await app.page.evaluate(() => {
      const l = window.egoexo.live.snapshot();
      return {
        frames: l.frames,
        latencies: l.latencies,
        arrivals: l.arrivals,
        posted: l.posted,
        compute: l.computeMs,
        lastLookahead: l.lastFrame?.lookahead,
        trained: l.lastFrame?.trained_for_lookahead,
      };
    });
    const p95 = percentile(after.latencies, 0.95);
    const goal = 100 + (lookahead * 1000) / 30;
    rows.push({
      lookahead,
      frames: after.frames - before.frames,
      latency_p50_ms: percentile(after.latencies, 0.5),
      latency_p95_ms: p95,
      goal_p95_ms: goal,
      meets_goal: p95 !== null && p95 <= goal,
      // The part before the page draws: device → relay → worker → reconstructed → posted.
      arrival_p50_ms: percentile(after.arrivals, 0.5),
      // … of which up to the worker's post: device → relay → worker, waiting, reconstructing.
      posted_p50_ms: percentile(after.posted, 0.5),
      posted_p95_ms: percentile(after.posted, 0.95),
      worker_ms_per_frame: median(after.compute),
      read_out_at: after.lastLookahead,
      // Read out by a live variant trained for this lookahead (else the offline networks).
      live_networks: after.trained ?? false,
    });
    console.error(`lookahead ${lookahead}: ${JSON.stringify(rows.at(-1))}`);
  }
  if (app.errors.length) throw new Error(`the page logged errors: ${JSON.stringify(app.errors)}`);
  console.log(`LIVEBENCH ${JSON.stringify({ seconds: SECONDS, rows })}`);
} finally {
  replay?.kill();
  await browser.close();
}
