// The detector step in the app's worker, end to end in headless Chromium: a session whose
// observers bring only video, detected in the page and compared with the CLI's detector.

import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { readFileSync, rmSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, test } from 'node:test';

import { OUT, chromiumForFile, openApp } from './browser.mjs';

const REPO = new URL('../../', import.meta.url).pathname;
// The CLI the tests make sessions with (the same build as the server's).
const BIN = process.env.EGOEXO_BIN ?? join(REPO, 'target/debug/egoexo');
// The tests' Python (PyAV decodes the video export); `cargo xtask test` sets it.
const PYTHON = process.env.EGOEXO_PYTHON;

const browser = chromiumForFile();

describe('observer video: the detector step in the worker', () => {
  // A simulated walk whose two observers bring only H.264 video (the wearer rendered through
  // each camera) and no keypoints, made by the CLI; the CLI's own detector step (OpenH264,
  // resample_rgb) on the same file is the reference for the page's (WebCodecs, canvas crop).
  test('a session with observer video and no keypoints reconstructs with its observers, detected in the worker', async () => {
    const session = join(OUT, 'walk-video.egoexo');
    const byCli = join(OUT, 'walk-video-cli.egoexo');
    execFileSync(BIN, ['walk', '--seconds', '4', '--video', '256', '--seed', '3', '-o', session], { stdio: ['ignore', 'ignore', 'inherit'] });
    execFileSync(BIN, ['keypoints', session, '-o', byCli, '--force', '--models', join(REPO, 'models')], { stdio: ['ignore', 'ignore', 'inherit'] });
    const app = await openApp(browser(), '?backend=webgl2');
    try {
      await app.waitState('idle');
      // Cancel while the detector runs: the job ends `cancelled`, nothing of it is kept.
      const file = { name: 'walk-video.egoexo', mimeType: 'application/zip', buffer: readFileSync(session) };
      const cancelling = app.page.evaluate(() => new Promise((resolve) => {
        const text = document.getElementById('progress-text');
        const observer = new MutationObserver(() => {
          if (!/^detecting keypoints .* — [1-9]\d*%$/.test(text.textContent)) return;
          observer.disconnect();
          document.getElementById('cancel-button').click();
          resolve(text.textContent);
        });
        observer.observe(text, { childList: true, characterData: true, subtree: true });
      }));
      await app.page.setInputFiles('#file-input', file);
      assert.match(await cancelling, /detecting keypoints/);
      assert.equal(await app.waitState(['cancelled', 'ready', 'error']), 'cancelled');
      await app.page.evaluate(() => {
        window.progressSeen = [];
        const text = document.getElementById('progress-text');
        new MutationObserver(() => window.progressSeen.push(text.textContent))
          .observe(text, { childList: true, characterData: true, subtree: true });
      });
      await app.page.setInputFiles('#file-input', file);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      const seen = await app.page.evaluate(() => window.progressSeen);
      assert.ok(seen.some((t) => /^detecting keypoints in the observers' video — \d+%$/.test(t)), JSON.stringify(seen.slice(0, 12)));
      const summary = await app.page.evaluate(() => window.egoexo.summary);
      assert.deepEqual(summary.detection.map((d) => d.observer), ['observer-1', 'observer-2']);
      for (const d of summary.detection) {
        assert.equal(d.frames, 120, JSON.stringify(d));
        assert.ok(d.detected >= 80, `the wearer is in view most of the walk: ${JSON.stringify(d)}`);
      }
      assert.ok(summary.exo_evidence_frames > 20, JSON.stringify(summary));
      assert.ok(Object.values(summary.observer_ray_frames).every((n) => n > 20), JSON.stringify(summary.observer_ray_frames));
      const facts = await app.text('#result-facts');
      assert.match(facts, /detector \(observer-1\)\s*the wearer in \d+ of 120 video frames, \d+\.\d detections\/s/);
      const rates = summary.detection.map((d) => d.detected / (d.ms / 1000));
      console.log(`detector step in the worker: ${summary.detection.map((d, i) => `${d.observer} ${d.detected}/${d.frames} frames, ${rates[i].toFixed(1)} detections/s`).join('; ')}`);
      writeFileSync(join(OUT, 'detection-worker.json'), JSON.stringify({ detection: summary.detection, detections_per_s: rates }, null, 1));

      // The page's keypoints against the CLI's: the same frames found, the same places.
      const [download] = await Promise.all([app.page.waitForEvent('download'), app.page.click('#save-session')]);
      const byPage = join(OUT, 'walk-video-page.egoexo');
      await download.saveAs(byPage);
      const compare = execFileSync(PYTHON ?? 'python3', ['-c', `
import json, sys, zipfile, statistics
def tracks(path):
    z = zipfile.ZipFile(path)
    out = {}
    for name in z.namelist():
        if name.endswith('keypoints.jsonl'):
            for line in z.read(name).decode().splitlines():
                r = json.loads(line)
                out.setdefault(r['observer'], {})[r['timestamp_ns']] = r['keypoints']
    return out
page, cli = tracks(sys.argv[1]), tracks(sys.argv[2])
report = {}
for obs, frames in cli.items():
    both = agree = 0
    errors = []
    for t, kps in frames.items():
        other = page[obs][t]
        has_a, has_b = any(k is not None for k in kps), any(k is not None for k in other)
        both += 1
        agree += has_a == has_b
        for a, b in zip(kps, other):
            if a is not None and b is not None:
                errors.append(((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2) ** 0.5)
    report[obs] = {'frames': both, 'same_detected': agree / both, 'median_px': statistics.median(errors), 'keypoints': len(errors)}
print(json.dumps(report))
`, byPage, byCli], { encoding: 'utf8' });
      const report = JSON.parse(compare);
      console.log(`page vs CLI keypoints: ${compare.trim()}`);
      assert.deepEqual(Object.keys(report).sort(), ['observer-1', 'observer-2']);
      for (const r of Object.values(report)) {
        assert.equal(r.frames, 120);
        assert.ok(r.same_detected >= 0.95, JSON.stringify(report));
        // 256 px images: two decoders and two resamplers, the same windows and mapping.
        assert.ok(r.median_px < 2.5, JSON.stringify(report));
      }
      // At import the page said where the keypoints would come from.
      assert.match(await app.text('#session-facts'), /video observers\/observer-1\/rgb\.mp4: keypoints found by the detector/);

      // The same session as a dropped folder (its MP4s among the files): the same step.
      const folder = join(OUT, 'walk-video-folder');
      rmSync(folder, { recursive: true, force: true });
      execFileSync(BIN, ['walk', '--seconds', '4', '--video', '256', '--seed', '3', '--folder', '-o', folder], { stdio: ['ignore', 'ignore', 'inherit'] });
      // The state is `ready` from the last run until the drop takes effect.
      await app.page.evaluate(() => { document.body.dataset.state = 'dropped'; });
      await app.page.setInputFiles('#folder-input', folder);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      const fromFolder = await app.page.evaluate(() => window.egoexo.summary);
      assert.deepEqual(fromFolder.detection.map((d) => [d.observer, d.detected]), summary.detection.map((d) => [d.observer, d.detected]));
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });
});
