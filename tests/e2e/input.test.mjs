// Bad input and failures in the app, end to end in headless Chromium: malformed files, dropped
// device folders, cancel, a pool of workers, a worker panic, damaged models, the backend choice.

import assert from 'node:assert/strict';
import { cpSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { describe, test } from 'node:test';

import { OUT, chromiumForFile, openApp } from './browser.mjs';

const REPO = new URL('../../', import.meta.url).pathname;
// A multi-device Aria MPS folder (egoexo-session's committed fixture).
const ARIA_FOLDER = join(REPO, 'crates/egoexo-session/tests/fixtures/aria_mps');
// The wearer's glasses as MPS writes them: trajectory/ (semidense points) + hand_tracking/ (v2),
// the right hand out of view from 0.2 to 0.5 s, the left from 0.8 to 1.3 s.
const HANDS_FOLDER = join(REPO, 'crates/egoexo-session/tests/fixtures/aria_mps_hands');

const browser = chromiumForFile();

describe('bad input and failures', () => {
  test('a malformed file shows the importer\'s exact message and the page keeps working', async () => {
    const app = await openApp(browser(), '?backend=webgl2');
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

  test('a dropped Aria MPS folder imports and reconstructs; a raw recording beside it is not read', async () => {
    // The fixture with the wearer's raw recording beside its MPS output, as a recording
    // folder often is (a real one is gigabytes): the page leaves it unread and says so.
    const dir = mkdtempSync(join(tmpdir(), 'egoexo-mps-vrs-'));
    const folder = join(dir, 'aria_mps');
    cpSync(ARIA_FOLDER, folder, { recursive: true });
    writeFileSync(join(folder, 'wearer', 'recording.vrs'), Buffer.alloc(4096, 7));
    const app = await openApp(browser(), '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#folder-input', folder);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      assert.match(await app.text('#session-facts'), /multi-device Aria MPS folder/);
      assert.match(await app.text('#frame-count'), /^\d+ frames$/);
      const warnings = await app.page.$$eval('#session-warnings li', (items) => items.map((li) => li.textContent));
      assert.ok(warnings.some((w) => /^aria_mps\/wearer\/recording\.vrs: not read \(0\.0 GiB\): a raw Aria recording/.test(w)), JSON.stringify(warnings));
      // No time_sync.csv in any device folder: the import says which clock it took as shared.
      assert.ok(warnings.some((w) => w.includes('no device folder has a time_sync.csv')), JSON.stringify(warnings));
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
      rmSync(dir, { recursive: true, force: true });
    }
  });

  test('a dropped Nymeria sequence with two participants (people files): both reconstructed, the cameras\' people associated', async () => {
    // The Nymeria fixture plus people files: the observer's camera sees the wearer and a
    // bystander, the wearer's camera the observer.
    const dir = mkdtempSync(join(tmpdir(), 'egoexo-nymeria-two-'));
    const sequence = join(dir, 'sequence');
    cpSync(join(REPO, 'crates/egoexo-session/tests/fixtures/nymeria'), sequence, { recursive: true });
    cpSync(join(REPO, 'crates/egoexo-session/tests/fixtures/nymeria_people'), sequence, { recursive: true });
    const app = await openApp(browser(), '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#folder-input', sequence);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      assert.deepEqual(await app.page.locator('#participants button').allTextContents(), ['wearer', 'observer']);
      const summary = await app.page.evaluate(() => window.egoexo.summary);
      assert.deepEqual(summary.participants.map((p) => p.id), ['wearer', 'observer']);
      assert.ok(summary.participants.every((p) => p.valid_frames > 0), JSON.stringify(summary.participants));
      const observerCamera = summary.association.find((a) => a.observer === 'observer');
      assert.equal(observerCamera.assigned.wearer, 61, JSON.stringify(summary.association));
      assert.ok(observerCamera.unassigned > 0, 'the bystander matches nobody');
      assert.match(await app.text('#result-facts'), /people \(observer\)\s*\d+ over \d+ frames: 61 to wearer; \d+ bystanders/);
      await app.page.click('[data-participant=observer]');
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      assert.equal(await app.page.evaluate(() => window.egoexo.summary.participant), 'observer');
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
      rmSync(dir, { recursive: true, force: true });
    }
  });

  test('an MPS folder with hand tracking: wrist coverage, the floor, 3-point with wrists that come and go, wrists drawn only where tracked', async () => {
    const app = await openApp(browser(), '?backend=webgl2');
    try {
      await app.waitState('idle');
      await app.page.setInputFiles('#folder-input', HANDS_FOLDER);
      assert.equal(await app.waitState(['ready', 'error']), 'ready', await app.text('#error-message'));
      const facts = await app.text('#session-facts');
      assert.match(facts, /single Aria MPS device folder/);
      // Warnings about the whole session read as sentences (no empty file name before a colon).
      const warnings = await app.page.$$eval('#session-warnings li', (items) => items.map((li) => li.textContent));
      assert.ok(warnings.some((w) => w.startsWith('one device: a session without observers')), JSON.stringify(warnings));
      assert.ok(warnings.every((w) => !w.startsWith(':') && !w.startsWith(' ')), JSON.stringify(warnings));
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
      await app.page.evaluate(() => window.egoexo.viewer.seek(20));
      await app.page.waitForTimeout(250);
      await app.page.screenshot({ path: join(OUT, 'mps-one-device.png') });
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });

  test('cancel stops the reconstruction between windows, and the same worker takes the next job', async () => {
    const app = await openApp(browser(), '?backend=webgl2');
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
      const app = await openApp(browser(), `?backend=webgl2&workers=${workers}`);
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
    const app = await openApp(browser(), '?backend=webgl2');
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
    const app = await openApp(browser(), '?backend=webgl2', { setup: count });
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
      const fresh = await openApp(browser(), '?backend=webgl2', { setup: corrupt });
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
    const app = await openApp(browser());
    try {
      assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
      assert.match(await app.text('#backend'), /renderer: (webgpu|webgl2)/i);
      assert.deepEqual(app.errors, []);
    } finally {
      await app.close();
    }
  });
});
