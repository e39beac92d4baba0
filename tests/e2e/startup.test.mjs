// Time to first skeleton in headless Chromium, cold and warm. A measurement: `cargo xtask test`
// runs it alone, after the other browser test files (`RUN_ALONE` in xtask/src/e2e.rs).

import assert from 'node:assert/strict';
import { writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { describe, test } from 'node:test';

import { OUT, chromiumForFile, openApp } from './browser.mjs';

const browser = chromiumForFile();

describe('startup', () => {
  test('time to first skeleton, cold and warm (performance marks; printed and kept in first-skeleton.json)', async () => {
    // `#sample` opens the sample as the page loads. Cold: a fresh context (empty HTTP cache
    // and Cache API). Warm: the same page reloaded (wasm from the HTTP cache, models from the
    // Cache API). Each time is the page's `egoexo:first-skeleton` mark (navigation start → the
    // frame after the scene was handed to the viewer).
    const app = await openApp(browser(), '?backend=webgl2#sample');
    // Also the worker's own account of the models: read (Cache API or network) and
    // check + load (sha256, tract), ms.
    const marks = () => app.page.evaluate(() => ({
      ...Object.fromEntries(['egoexo:models-ready', 'egoexo:imported', 'egoexo:first-skeleton'].map((name) => [
        name.replace('egoexo:', ''), performance.getEntriesByName(name, 'mark')[0]?.startTime ?? null,
      ])),
      'models-read': window.egoexo.models?.read_ms ?? null,
      'models-load': window.egoexo.models?.load_ms ?? null,
      'models-cached-files': window.egoexo.models?.cached_files ?? null,
    }));
    const firstSkeleton = async () => {
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      await app.page.waitForFunction(() => performance.getEntriesByName('egoexo:first-skeleton', 'mark').length > 0,
        null, { timeout: 60_000, polling: 50 });
      return marks();
    };
    try {
      const cold = await firstSkeleton();
      await app.page.reload();
      const warm = await firstSkeleton();
      for (const [name, run] of [['cold', cold], ['warm', warm]]) {
        for (const [mark, ms] of Object.entries(run)) {
          assert.ok(Number.isFinite(ms) && ms >= 0, `${name} ${mark}: ${ms}`);
        }
        assert.ok(run.imported <= run['first-skeleton'], `${name}: ${JSON.stringify(run)}`);
        assert.ok(run['models-read'] + run['models-load'] <= run['models-ready'], `${name}: ${JSON.stringify(run)}`);
      }
      // Cold: every model from the network; warm: every one from the Cache API.
      assert.equal(cold['models-cached-files'], 0);
      assert.ok(warm['models-cached-files'] > 0, JSON.stringify(warm));
      const report = { cold_ms: cold, warm_ms: warm, goal_warm_first_skeleton_ms: 2000 };
      writeFileSync(join(OUT, 'first-skeleton.json'), `${JSON.stringify(report, null, 1)}\n`);
      console.log(`time to first skeleton: cold ${cold['first-skeleton'].toFixed(0)} ms, warm ${warm['first-skeleton'].toFixed(0)} ms`
        + ` (models ready ${cold['models-ready'].toFixed(0)} / ${warm['models-ready'].toFixed(0)} ms: read`
        + ` ${cold['models-read']} / ${warm['models-read']}, check + load ${cold['models-load']} / ${warm['models-load']})`);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });
});
