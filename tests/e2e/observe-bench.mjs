// The observer page's detection rate (issue 41's goal: ≥ 15 frames/s on this machine's
// headless Chromium): the page alone — a room, a film of a wearer as its camera, no page
// watching and no replay — with one detector and with two side by side, read once a second.
// Usage: node tests/e2e/observe-bench.mjs [seconds]  (EGOEXO_E2E_URL, EGOEXO_BIN)
// Prints `OBSERVEBENCH {json}`: per detector count the median, lowest and highest rate
// (frames/s) and the median ms a detection.

import { execFileSync } from 'node:child_process';
import { mkdtempSync, readdirSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

import { APP_URL, EGOEXO, launch, openApp } from './browser.mjs';

const SECONDS = Number(process.argv[2] ?? 10);
const median = (values) => [...values].sort((a, b) => a - b)[Math.floor((values.length - 1) / 2)];

const dir = mkdtempSync(join(tmpdir(), 'egoexo-observe-bench-'));
let browser;
try {
  // The film of the observer page's test: a wearer wandering before a tripod, 480 × 480.
  execFileSync(EGOEXO, [
    'walk', '--seconds', '20', '--wander', '--observers', '1', '--static-cameras', '--video', '480',
    '--y4m', join(dir, 'cameras'), '-o', join(dir, 'walk.egoexo'), '--seed', '5',
  ], { stdio: ['ignore', 'ignore', 'inherit'] });
  const film = join(dir, 'cameras', readdirSync(join(dir, 'cameras')).find((f) => f.endsWith('.y4m')));
  const response = await fetch(new URL('api/live/rooms', APP_URL), { method: 'POST' });
  if (!response.ok) throw new Error(`making a room: HTTP ${response.status}`);
  const room = await response.json();
  browser = await launch([
    '--use-fake-device-for-media-stream',
    '--use-fake-ui-for-media-stream',
    `--use-file-for-fake-video-capture=${film}`,
  ]);
  const rows = [];
  for (const detectors of [1, 2]) {
    const camera = await openApp(browser, '', { path: `observe.html?detectors=${detectors}&device=bench-${detectors}#live=${room.room}.${room.device_secret}` });
    try {
      await camera.waitState(['ready', 'error', 'unsupported'], 60_000);
      await camera.page.getByRole('button', { name: 'Start observing' }).click();
      const state = await camera.waitState(['observing', 'error'], 60_000);
      if (state !== 'observing') throw new Error(`the camera page: ${await camera.text('#error-message')}`);
      // Past the models' loading and the first detections.
      await camera.page.waitForFunction(() => Number(document.body.dataset.detections) >= 10, null, { timeout: 60_000 });
      const rates = [];
      const ms = [];
      for (let s = 0; s < SECONDS; s += 1) {
        await camera.page.waitForTimeout(1000);
        const text = await camera.text('#detect-rate');
        const m = text.match(/^(\d+) frames\/s, (\d+) ms each/);
        if (m) {
          rates.push(Number(m[1]));
          ms.push(Number(m[2]));
        }
      }
      if (rates.length === 0) throw new Error(`no detection rate read (${await camera.text('#detect-rate')})`);
      rows.push({ detectors, median_fps: median(rates), min_fps: Math.min(...rates), max_fps: Math.max(...rates), median_ms: median(ms), readings: rates.length });
    } finally {
      await camera.close();
    }
  }
  console.log(`OBSERVEBENCH ${JSON.stringify({ seconds: SECONDS, goal_fps: 15, rows })}`);
} finally {
  await browser?.close();
  rmSync(dir, { recursive: true, force: true });
}
