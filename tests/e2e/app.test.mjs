// The app end to end in headless Chromium, against dist/ as `cargo xtask serve` builds it.
// Run by `cargo xtask test` (EGOEXO_E2E_URL points at the served dist/); screenshots go to
// target/e2e/.

import assert from 'node:assert/strict';
import { readFileSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { after, before, describe, test } from 'node:test';

import { OUT, decodePng, launch, openApp, savePng, skeletonPixels } from './browser.mjs';

const REPO = new URL('../../', import.meta.url).pathname;
const SAMPLES = JSON.parse(readFileSync(join(REPO, 'public/samples/samples.json'), 'utf8'));
const SAMPLE = SAMPLES.samples[0];
// A multi-device Aria MPS folder (egoexo-session's committed fixture).
const ARIA_FOLDER = join(REPO, 'crates/egoexo-session/tests/fixtures/aria_mps');
// The wearer's glasses as MPS writes them: trajectory/ (semidense points) + hand_tracking/ (v2),
// the right hand out of view from 0.2 to 0.5 s, the left from 0.8 to 1.3 s.
const HANDS_FOLDER = join(REPO, 'crates/egoexo-session/tests/fixtures/aria_mps_hands');
// Skeleton pixels of each side a drawn body must show (a blank or background-only canvas has
// none; the body is small in the viewer's whole-scene framing).
const MIN_SIDE_PIXELS = 20;

let browser;
before(async () => {
  browser = await launch();
});
after(async () => {
  await browser?.close();
});

describe('the sample, WebGL2 canvas', () => {
  let app;
  before(async () => {
    app = await openApp(browser, '?backend=webgl2');
  });
  after(async () => {
    await app?.close();
  });

  test('reconstructs with a real progress bar and shows the frame count', async () => {
    const { page } = app;
    assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
    assert.match(await app.text('#backend'), /webgl2/i);
    const seen = [];
    const watcher = setInterval(async () => {
      try {
        seen.push(await page.evaluate(() => [document.getElementById('progress').value, document.getElementById('progress-text').textContent]));
      } catch {}
    }, 50);
    await page.click('#sample-button');
    const state = await app.waitState(['ready', 'error']);
    clearInterval(watcher);
    assert.equal(state, 'ready', await app.text('#error-message'));
    assert.equal(await app.text('#frame-count'), `${SAMPLE.frames} frames`);
    assert.equal(await page.evaluate(() => window.egoexo.viewer.frames()), SAMPLE.frames);
    assert.ok(seen.some(([v]) => v > 0 && v < 1), `no intermediate progress seen: ${JSON.stringify(seen.slice(0, 20))}`);
    assert.ok(seen.some(([, t]) => /exo fusion/.test(t)), 'the fusion stage was shown');
    const facts = await app.text('#session-facts');
    assert.match(facts, /observer-1/);
    assert.match(facts, /3-point tracking/);
    assert.match(await app.text('#result-facts'), /MPJPE vs ground truth/);
    // The ego-only overlay reuses the ego pass: EgoNet ran once per window for the whole job,
    // and the overlay ran the shipped fusion with every observer masked (fusion_ego_only).
    const summary = await page.evaluate(() => window.egoexo.summary);
    assert.ok(summary.windows > 0, JSON.stringify(summary));
    const w = summary.windows;
    assert.deepEqual(summary.network_runs, { egonet: w, gate: w, fusion: w, fusion_ego_only: w });
  });

  test('plays: the frame advances, and the timeline steps and scrubs', async () => {
    const { page } = app;
    const frame = () => page.evaluate(() => window.egoexo.viewer.frame());
    const first = await frame();
    await page.waitForTimeout(600);
    assert.notEqual(await frame(), first, 'the skeleton moves');
    await page.click('#play-button');
    assert.equal(await page.evaluate(() => window.egoexo.viewer.is_playing()), false);
    await page.evaluate(() => {
      const scrubber = document.getElementById('scrubber');
      scrubber.value = '300';
      scrubber.dispatchEvent(new Event('input'));
    });
    assert.equal(await frame(), 300);
    await page.click('#step-forward');
    assert.equal(await frame(), 301);
    await page.waitForFunction(() => document.getElementById('frame-readout').textContent.startsWith('frame 302 /'));
  });

  test('draws the skeleton (screenshot has its colours)', async () => {
    const { page } = app;
    await page.screenshot({ path: join(OUT, 'app-webgl2.png') });
    await page.uncheck('#show-rays');
    await page.uncheck('#show-ground-truth');
    await page.evaluate(() => window.egoexo.viewer.seek(300));
    await page.waitForTimeout(300);
    const shot = await page.locator('#view').screenshot({ path: join(OUT, 'sample-webgl2.png') });
    const { rgba } = decodePng(shot);
    const { left, right } = skeletonPixels(rgba);
    assert.ok(left >= MIN_SIDE_PIXELS && right >= MIN_SIDE_PIXELS, `skeleton pixels: left ${left}, right ${right}`);
  });

  test('the toggles change the picture', async () => {
    const { page } = app;
    const before = decodePng(await page.locator('#view').screenshot()).rgba;
    await page.check('#show-ego-only');
    await page.check('#show-rays');
    await page.waitForTimeout(300);
    const after = decodePng(await page.locator('#view').screenshot({ path: join(OUT, 'sample-ego-only-overlay.png') })).rgba;
    let changed = 0;
    for (let i = 0; i < before.length; i += 4) if (before[i] !== after[i] || before[i + 2] !== after[i + 2]) changed += 1;
    assert.ok(changed > 100, `${changed} pixels changed`);
  });

  test('exports download the worker\'s files', async () => {
    const { page } = app;
    const expectations = { bvh: 'HIERARCHY', csv: 'frame,time_s', glb: 'glTF', npz: 'PK' };
    for (const [format, magic] of Object.entries(expectations)) {
      const [download] = await Promise.all([page.waitForEvent('download'), page.click(`[data-format=${format}]`)]);
      const session = await page.evaluate(() => window.egoexo.session.name);
      assert.equal(download.suggestedFilename(), `${session}-ego-exo.${format}`);
      const path = join(OUT, `export.${format}`);
      await download.saveAs(path);
      assert.equal(readFileSync(path).subarray(0, magic.length).toString('latin1'), magic, format);
    }
    await app.waitState('ready');
  });

  test('WebGPU renders the scene off-screen (pixel read-back)', async () => {
    const { page } = app;
    const result = await page.evaluate(async () => {
      const { Viewer } = window.egoexo;
      const [w, h] = [960, 720];
      try {
        const rgba = await Viewer.render_offscreen(window.egoexo.scene, 300, w, h, 'webgpu');
        let binary = '';
        for (let i = 0; i < rgba.length; i += 0x8000) binary += String.fromCharCode(...rgba.subarray(i, i + 0x8000));
        return { w, h, base64: btoa(binary) };
      } catch (error) {
        return { error: String(error?.message ?? error) };
      }
    });
    assert.equal(result.error, undefined, `render_offscreen failed: ${result.error}`);
    const rgba = Buffer.from(result.base64, 'base64');
    assert.equal(rgba.length, result.w * result.h * 4);
    savePng('offscreen-webgpu.png', result.w, result.h, rgba);
    const { left, right } = skeletonPixels(rgba);
    assert.ok(left >= MIN_SIDE_PIXELS && right >= MIN_SIDE_PIXELS, `skeleton pixels: left ${left}, right ${right}`);
  });

  test('no console errors, no uncaught exceptions', () => {
    assert.deepEqual(app.errors, []);
  });
});

describe('bad input and failures', () => {
  test('a malformed file shows the importer\'s exact message and the page keeps working', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#file-input', { name: 'broken.egoexo', mimeType: 'application/zip', buffer: Buffer.from('this is not a zip archive') });
      assert.equal(await app.waitState(['error', 'ready']), 'error');
      assert.equal(await app.text('#error-title'), 'Could not import the session');
      assert.match(await app.text('#error-message'), /^broken\.egoexo: not a readable zip archive \(truncated or corrupt\?\): /);

      // Dropped onto the page: a zip of something that is no session names what it holds.
      await app.page.click('#error-dismiss');
      const dataTransfer = await app.page.evaluateHandle(() => {
        const dt = new DataTransfer();
        dt.items.add(new File(['just some notes'], 'notes.txt', { type: 'text/plain' }));
        return dt;
      });
      await app.page.dispatchEvent('#drop-zone', 'drop', { dataTransfer });
      assert.equal(await app.waitState(['error', 'ready']), 'error');
      assert.match(await app.text('#error-message'), /^notes\.txt: not a readable zip archive/);

      // Not frozen, not blank: the controls answer and the canvas is still there.
      assert.equal(await app.page.locator('#sample-button').isEnabled(), true);
      assert.equal(await app.page.locator('#view').isVisible(), true);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('a dropped Aria MPS folder imports and reconstructs', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#folder-input', ARIA_FOLDER);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      assert.match(await app.text('#session-facts'), /multi-device Aria MPS folder/);
      assert.match(await app.text('#frame-count'), /^\d+ frames$/);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('an MPS folder with hand tracking: wrist coverage, the floor, 3-point with wrists that come and go, wrists drawn only where tracked', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#folder-input', HANDS_FOLDER);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      const facts = await app.text('#session-facts');
      assert.match(facts, /single Aria MPS device folder/);
      assert.match(facts, /3-point tracking: head, left_wrist, right_wrist \(the wrists are tracked on \d+% \(left\) and \d+% \(right\) of the head's frames: the 3-point model uses them where they are/);
      assert.match(facts, /left wrist\s*tracked on \d+\.\d% of frames, longest gap 0\.[45]\d s \(MPS wrist_and_palm_poses\.csv v2/);
      assert.match(facts, /right wrist\s*tracked on \d+\.\d% of frames, longest gap 0\.[23]\d s/);
      assert.match(facts, /floor\s*-?0\.0\d\d m, from semidense points \(\d+ well-constrained points at the floor/);
      const scene = await app.page.evaluate(() => {
        const raw = window.egoexo.scene;
        const s = typeof raw === 'string' ? JSON.parse(raw)
          : (raw instanceof ArrayBuffer || ArrayBuffer.isView(raw)) ? JSON.parse(new TextDecoder().decode(raw)) : raw;
        return { floor_y: s.floor_y, fps: s.fps, devices: s.devices.map((d) => ({ name: d.name, valid: d.valid })) };
      });
      assert.ok(Math.abs(scene.floor_y) < 0.01, `the scene stands on the session's floor: ${scene.floor_y}`);
      const valid = (name, t) => scene.devices.find((d) => d.name === name).valid[Math.round(t * scene.fps)];
      assert.equal(valid('right_wrist', 0.35), false, 'the right wrist is not drawn while out of view');
      assert.equal(valid('right_wrist', 1.0), true);
      assert.equal(valid('left_wrist', 1.0), false, 'the left wrist is not drawn while out of view');
      assert.equal(valid('left_wrist', 0.4), true);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('cancel stops the reconstruction between windows, and the same worker takes the next job', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      // Cancel as soon as the page shows a reconstruction stage, in the page itself: a click
      // from the test process could come after the (quick) reconstruction has finished.
      const stage = await app.page.evaluate(() => new Promise((resolve) => {
        window.workerEvents = [];
        window.egoexo.worker.addEventListener('message', (e) => window.workerEvents.push([e.data.type, e.data.job]));
        window.workerBeforeCancel = window.egoexo.worker;
        const text = document.getElementById('progress-text');
        const observer = new MutationObserver(() => {
          if (!/ego pass|exo fusion|overlay/.test(text.textContent)) return;
          observer.disconnect();
          window.cancelledJob = window.egoexo.client.current_job();
          document.getElementById('cancel-button').click();
          resolve(text.textContent);
        });
        observer.observe(text, { childList: true, characterData: true, subtree: true });
        document.getElementById('sample-button').click();
      }));
      assert.match(stage, /ego pass|exo fusion|overlay/);
      assert.equal(await app.waitState(['cancelled', 'ready']), 'cancelled');
      // The worker answers the cancel itself, and the cancelled job never delivers a result.
      await app.page.waitForFunction(() => window.workerEvents.some(([type, job]) => type === 'cancelled' && job === window.cancelledJob));
      await app.page.waitForTimeout(500);
      assert.equal(await app.page.evaluate(() => document.body.dataset.state), 'cancelled');
      const results = await app.page.evaluate(() => window.workerEvents.filter(([type, job]) => type === 'reconstructed' && job === window.cancelledJob));
      assert.deepEqual(results, []);
      assert.equal(await app.text('#error-title'), 'Cancelled');
      assert.equal(await app.page.locator('#progress-panel').isHidden(), true);
      // The same worker (its models still loaded) answers the next job: a quick failing import.
      assert.equal(await app.page.evaluate(() => window.egoexo.worker === window.workerBeforeCancel), true);
      await app.page.setInputFiles('#file-input', { name: 'empty.zip', mimeType: 'application/zip', buffer: Buffer.alloc(0) });
      assert.equal(await app.waitState(['error', 'ready']), 'error');
      assert.match(await app.text('#error-message'), /^empty\.zip: the file is empty/);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('a pool of two workers reconstructs the sample byte for byte as one worker does', async () => {
    // The npz export and the summary of the sample with `workers` workers. A short session's
    // first job leaves the helpers for later (they start once it is done), so with a pool the
    // sample runs again until the helper has computed chunks of a job (at most `runs` times).
    const reconstruct = async (workers, runs) => {
      const app = await openApp(browser, `?backend=webgl2&workers=${workers}`);
      try {
        assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
        const summaries = [];
        for (let run = 0; run < runs; run++) {
          // The state is `ready` from the last run until the click takes effect.
          await app.page.evaluate(() => {
            document.body.dataset.state = 'clicked';
            document.getElementById('sample-button').click();
          });
          assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
          summaries.push(await app.page.evaluate(() => window.egoexo.summary));
          if (summaries.at(-1).pool?.helper_chunks > 0) break;
        }
        const [download] = await Promise.all([app.page.waitForEvent('download'), app.page.click('[data-format=npz]')]);
        const path = join(OUT, `pool-${workers}.npz`);
        await download.saveAs(path);
        assert.deepEqual(app.errors, []);
        return { npz: readFileSync(path), summaries };
      } finally {
        await app.close();
      }
    };
    const one = await reconstruct(1, 1);
    const two = await reconstruct(2, 6);
    assert.equal(one.summaries[0].pool, undefined, JSON.stringify(one.summaries[0]));
    assert.equal(two.summaries[0].pool, undefined, 'the first job of a short session runs in one worker');
    const last = two.summaries.at(-1);
    const pool = last.pool;
    assert.ok(pool, JSON.stringify(two.summaries));
    assert.equal(pool.workers, 2);
    assert.equal(pool.failed_helpers, 0);
    assert.ok(pool.chunks >= 2 && pool.helper_chunks > 0 && pool.helper_chunks <= pool.chunks, JSON.stringify(pool));
    console.log(`# pool of 2 (job ${two.summaries.length}): ${pool.helper_chunks} of ${pool.chunks} chunks (${pool.chunk_windows} windows each) computed by the helper`);
    assert.deepEqual(last.network_runs, one.summaries[0].network_runs);
    assert.ok(one.npz.equals(two.npz), 'the pooled reconstruction differs from the single worker\'s');
  });

  test('a worker panic is caught, reported, and the worker replaced', async () => {
    const app = await openApp(browser, '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.evaluate(() => window.egoexo.client.panic_for_test());
      assert.equal(await app.waitState(['error']), 'error');
      assert.match(await app.text('#error-title'), /worker crashed/);
      assert.match(await app.text('#error-message'), /a panic requested by the test suite/);
      await app.page.setInputFiles('#file-input', { name: 'broken.zip', mimeType: 'application/zip', buffer: Buffer.from('nope') });
      await app.page.waitForFunction(() => document.getElementById('error-title').textContent === 'Could not import the session');
      // The only console errors are the panic's own report.
      assert.ok(app.errors.length > 0 && app.errors.every((e) => e.includes('panicked')), app.errors.join('\n'));
    } finally {
      await app.close();
    }
  });

  test('models are fetched once, then come from the Cache API; a damaged model is refused', async () => {
    let fetched = 0;
    const count = (context) => context.route('**/*.onnx', (route) => {
      fetched += 1;
      return route.continue();
    });
    const app = await openApp(browser, '?backend=webgl2', { setup: count });
    try {
      await app.waitState('idle');
      const cached = () => app.page.evaluate(async () => (await (await caches.open('egoexo-models')).keys()).length);
      // Every model fetched so far is in the cache (the downloads run in parallel: wait for all).
      for (let tries = 0; fetched === 0 || (await cached()) < fetched; tries += 1) {
        assert.ok(tries < 1200, 'the models were never cached');
        await app.page.waitForTimeout(100);
      }
      const first = fetched;
      assert.ok(first > 0, 'the models were fetched');
      await app.page.reload();
      await app.waitState('idle');
      // Open something, so the new worker has certainly loaded its models.
      await app.page.setInputFiles('#file-input', { name: 'x.zip', mimeType: 'application/zip', buffer: Buffer.from('x') });
      assert.equal(await app.waitState(['error', 'ready']), 'error');
      assert.equal(await app.text('#error-title'), 'Could not import the session');
      assert.equal(fetched, first, 'no model was fetched again');

      // A corrupted download in a fresh context: the sha256 check names the file.
      const corrupt = async (context) => {
        await context.route('**/*.onnx', async (route) => {
          const response = await route.fetch({ timeout: 120_000 });
          const body = Buffer.from(await response.body());
          body[body.length >> 1] ^= 0xff;
          await route.fulfill({ response, body });
        });
      };
      const fresh = await openApp(browser, '?backend=webgl2', { setup: corrupt });
      try {
        // The worker loads the models as the page starts: the failure shows without a click.
        await fresh.waitState('error', 120_000);
        assert.equal(await fresh.text('#error-title'), 'Could not load the models');
        assert.match(await fresh.text('#error-message'), /\.onnx` does not match the manifest: sha256 [0-9a-f]{64}, expected [0-9a-f]{64}/);
        // Trying a session tries the models again, and fails the same way.
        await fresh.page.click('#error-dismiss');
        await fresh.page.click('#sample-button');
        await fresh.page.waitForFunction(() => !document.getElementById('error-panel').hidden, null, { timeout: 120_000 });
        assert.equal(await fresh.text('#error-title'), 'Could not load the models');
      } finally {
        await fresh.close();
      }
    } finally {
      await app.close();
    }
  });

  test('the automatic backend choice ends with a working renderer', async () => {
    const app = await openApp(browser);
    try {
      assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
      assert.match(await app.text('#backend'), /renderer: (webgpu|webgl2)/i);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });
});

describe('startup', () => {
  test('time to first skeleton, cold and warm (performance marks; printed and kept in first-skeleton.json)', async () => {
    // `#sample` opens the sample as the page loads. Cold: a fresh context (empty HTTP cache
    // and Cache API). Warm: the same page reloaded (wasm from the HTTP cache, models from the
    // Cache API). Each time is the page's `egoexo:first-skeleton` mark (navigation start → the
    // frame after the scene was handed to the viewer).
    const app = await openApp(browser, '?backend=webgl2#sample');
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
