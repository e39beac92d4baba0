// An hour-long session in the browser: 108,000 frames (30 fps) of a wearer walking in a circle
// watched by two observers (`egoexo walk --seconds 3600`), imported, reconstructed by the
// worker's pool with progress throughout, cancelled part-way, opened and reconstructed again
// to the end, and drawn. Chromium's peak resident memory is measured (VmHWM of its processes) and printed.

import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { readFileSync, readdirSync, statSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { after, before, describe, test } from 'node:test';

import { OUT, launch, openApp } from './browser.mjs';

const REPO = new URL('../../', import.meta.url).pathname;
const BIN = process.env.EGOEXO_BIN ?? join(REPO, 'target/debug/egoexo');
const SECONDS = Number(process.env.EGOEXO_HOUR_SECONDS ?? 3600);
const FRAMES = Math.round(SECONDS * 30);
// The pool's size (`?workers=N`); the page's default when unset.
const WORKERS = process.env.EGOEXO_HOUR_WORKERS;

/// Peak resident memory (VmHWM, bytes) of every process of the browser, by pid.
function chromiumPeaks() {
  const peaks = {};
  for (const pid of readdirSync('/proc').filter((p) => /^\d+$/.test(p))) {
    try {
      const status = readFileSync(`/proc/${pid}/status`, 'utf8');
      if (!/^Name:\s*(chrom|headless)/m.test(status)) continue;
      const hwm = /^VmHWM:\s*(\d+) kB/m.exec(status);
      if (hwm) peaks[pid] = Number(hwm[1]) * 1024;
    } catch {}
  }
  return peaks;
}

let browser;
let session;
before(async () => {
  session = join(OUT, `walk-${SECONDS}s.egoexo`);
  const started = Date.now();
  execFileSync(BIN, ['walk', '--seconds', String(SECONDS), '--observers', '2', '-o', session], { stdio: 'inherit' });
  console.log(`# wrote ${(statSync(session).size / 1e6).toFixed(1)} MB in ${((Date.now() - started) / 1000).toFixed(1)} s`);
  browser = await launch();
});
after(async () => {
  await browser?.close();
});

describe('an hour-long session', () => {
  test('imports, reconstructs with progress and cancel throughout, and is drawn, within bounded memory', async () => {
    const app = await openApp(browser, `?backend=webgl2${WORKERS ? `&workers=${WORKERS}` : ''}`);
    const { page } = app;
    let watch;
    try {
      assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
      const progress = [];
      watch = setInterval(async () => {
        try {
          progress.push(await page.evaluate(() => [performance.now(), document.getElementById('progress').value, document.getElementById('progress-text').textContent]));
        } catch {}
      }, 250);
      const opened = Date.now();
      // Cancel in the page as soon as a third of the windows are through.
      const cancelledAt = page.evaluate(() => new Promise((resolve) => {
        const bar = document.getElementById('progress');
        const poll = setInterval(() => {
          if (!/ego pass|exo fusion|overlay/.test(document.getElementById('progress-text').textContent) || bar.value < 0.33) return;
          clearInterval(poll);
          document.getElementById('cancel-button').click();
          resolve(bar.value);
        }, 20);
      }));
      await page.setInputFiles('#file-input', session);
      const at = await cancelledAt;
      assert.equal(await app.waitState(['cancelled', 'ready', 'error']), 'cancelled', await app.text('#error-message'));
      const cancelSeconds = (Date.now() - opened) / 1000;
      assert.ok(at >= 0.33 && at < 1, `cancelled at ${at}`);
      // Again, to the end (opened again, as a user would).
      const rerun = Date.now();
      await page.setInputFiles('#file-input', session);
      assert.equal(await app.waitState(['ready', 'error'], 1_200_000), 'ready', await app.text('#error-message'));
      const seconds = (Date.now() - rerun) / 1000;
      clearInterval(watch);
      assert.equal(await app.text('#frame-count'), `${FRAMES} frames`);
      assert.equal(await page.evaluate(() => window.egoexo.viewer.frames()), FRAMES);
      const summary = await page.evaluate(() => window.egoexo.summary);
      assert.equal(summary.frames, FRAMES);
      assert.ok(summary.valid_frames > 0.99 * FRAMES, JSON.stringify(summary));
      // Progress moved through both runs: many distinct values.
      const values = progress.map(([, v]) => v);
      const expected = Math.min(20, Math.floor((summary.pool?.chunks ?? summary.windows) / 2));
      assert.ok(new Set(values.map((v) => v.toFixed(2))).size >= expected, `progress values: ${[...new Set(values)].slice(0, 40)}`);
      // The page keeps drawing: a frame can be picked and shown.
      await page.evaluate((f) => window.egoexo.viewer.seek(f), FRAMES - 10);
      const peaks = chromiumPeaks();
      const peak = Math.max(...Object.values(peaks));
      const total = Object.values(peaks).reduce((a, b) => a + b, 0);
      const result = {
        frames: FRAMES,
        cancel_after_s: cancelSeconds,
        reconstruct_s: seconds,
        fps: FRAMES / seconds,
        pool: summary.pool ?? null,
        peak_process_mb: peak / 1e6,
        sum_of_peaks_mb: total / 1e6,
      };
      writeFileSync(join(OUT, 'hour.json'), JSON.stringify(result, null, 2));
      console.log(`# hour-long session: ${FRAMES} frames imported and reconstructed in ${seconds.toFixed(1)} s (${result.fps.toFixed(0)} frames/s)`
        + ` with ${summary.pool?.workers ?? 1} workers; cancelled after ${cancelSeconds.toFixed(1)} s; `
        + `Chromium peak ${result.peak_process_mb.toFixed(0)} MB in one process, ${result.sum_of_peaks_mb.toFixed(0)} MB summed`);
      // The worker's wasm memory cannot pass 4 GiB; the renderer holding the page and every
      // worker stays well below what this machine has.
      assert.ok(peak < 6e9, `peak ${peak / 1e6} MB`);
      assert.deepEqual(app.errors, []);
    } finally {
      clearInterval(watch);
      await app.close();
    }
  });
});
