// The app end to end in headless Chromium, against dist/ as `cargo xtask serve` builds it: the
// sample reconstructed, drawn, played and exported. Run by `cargo xtask test` (EGOEXO_E2E_URL
// points at the served dist/); screenshots go to target/e2e/. The other files: input.test.mjs
// (bad input and failures), detect.test.mjs (the detector step), startup.test.mjs (time to
// first skeleton).

import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { readFileSync } from 'node:fs';
import { join } from 'node:path';
import { after, before, describe, test } from 'node:test';

import { OUT, chromiumForFile, decodePng, openApp, savePng, skeletonPixels } from './browser.mjs';

const REPO = new URL('../../', import.meta.url).pathname;
// The tests' Python (PyAV decodes the video export); `cargo xtask test` sets it.
const PYTHON = process.env.EGOEXO_PYTHON;
const SAMPLES = JSON.parse(readFileSync(join(REPO, 'public/samples/samples.json'), 'utf8'));
const SAMPLE = SAMPLES.samples[0];
// Skeleton pixels of each side a drawn body must show (a blank or background-only canvas has
// none; the body is small in the viewer's whole-scene framing).
const MIN_SIDE_PIXELS = 20;

const browser = chromiumForFile();

describe('the sample, WebGL2 canvas', () => {
  let app;
  before(async () => {
    app = await openApp(browser(), '?backend=webgl2');
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

  test('opens paused (reduced motion asked for), plays on Play: the frame advances, and the timeline steps and scrubs', async () => {
    const { page } = app;
    const frame = () => page.evaluate(() => window.egoexo.viewer.frame());
    const playing = () => page.evaluate(() => window.egoexo.viewer.is_playing());
    assert.equal(await playing(), false, 'the page asked for reduced motion: the first frame waits for Play');
    assert.equal(await frame(), 0);
    assert.equal(await app.text('#play-button'), 'Play');
    await page.click('#play-button');
    assert.equal(await playing(), true);
    await page.waitForFunction(() => window.egoexo.viewer.frame() > 0, null, { timeout: 10_000 });
    assert.equal(await app.text('#play-button'), 'Pause');
    await page.click('#play-button');
    assert.equal(await playing(), false);
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

  test('the viewer: a body of capsules (B: stick figures), the follow camera, each observer\'s view (O), the help overlay (?)', async () => {
    const { page } = app;
    const viewer = (f, ...args) => page.evaluate(([f, args]) => window.egoexo.viewer[f](...args), [f, args]);
    const shot = async (name) => decodePng(await page.locator('#view').screenshot(name ? { path: join(OUT, name) } : {}));
    const settle = () => page.waitForTimeout(250);
    await viewer('pause');
    await page.uncheck('#show-rays');
    await page.uncheck('#show-ego-only');
    await page.uncheck('#show-ground-truth');
    await page.uncheck('#follow');
    await viewer('reset_camera');
    await viewer('seek', 300);
    await settle();
    const body = skeletonPixels((await shot('sample-body.png')).rgba);
    await page.keyboard.press('b');
    await settle();
    assert.equal(await page.isChecked('#show-body'), false, 'B switches to stick figures');
    const stick = skeletonPixels((await shot('sample-stick.png')).rgba);
    await page.keyboard.press('b');
    assert.equal(await page.isChecked('#show-body'), true);
    // Capsules sized like a body cover several times the stick figure's pixels.
    assert.ok(body.left > 1.8 * stick.left && body.right > 1.8 * stick.right,
      `body ${JSON.stringify(body)} vs stick ${JSON.stringify(stick)}`);

    // Following: the wearer stays near the middle of the view wherever it walks.
    await page.keyboard.press('f');
    assert.equal(await page.isChecked('#follow'), true);
    assert.equal(await viewer('follows'), true);
    const centroid = ({ rgba, width, height }) => {
      let n = 0; let sx = 0; let sy = 0;
      for (let i = 0; i < rgba.length; i += 4) {
        const [r, g, b] = [rgba[i], rgba[i + 1], rgba[i + 2]];
        const left = b >= 140 && r <= 0.4 * b && g <= 0.65 * b && g >= r;
        const right = r >= 140 && g <= 0.58 * r && g >= 0.28 * r && b <= 0.3 * r;
        if (left || right) { const p = i / 4; sx += p % width; sy += Math.floor(p / width); n += 1; }
      }
      return { x: sx / n / width, y: sy / n / height, n };
    };
    const followed = [];
    for (const frame of [60, 600, 1100]) {
      await viewer('seek', frame);
      await settle();
      followed.push(centroid(await shot(`sample-follow-${frame}.png`)));
    }
    for (const c of followed) {
      assert.ok(c.n > 200 && Math.abs(c.x - 0.5) < 0.15 && Math.abs(c.y - 0.5) < 0.25, `followed body at ${JSON.stringify(c)}`);
    }
    await page.keyboard.press('f');
    assert.equal(await viewer('follows'), false);

    // Through each observer's camera: its frustum becomes the view, its keypoints (gate-coloured
    // markers) are drawn over the body; O cycles orbit → observer 1 → observer 2 → orbit.
    // Rays off: the only gate-coloured things in an observer's view are its own keypoints.
    await page.uncheck('#show-rays');
    const ids = await viewer('observer_ids');
    assert.ok(ids.length >= 1, 'the sample has observers');
    // For each observer, a frame where it sees the wearer (the most keypoints with rays).
    const seeing = await page.evaluate(() => {
      const raw = window.egoexo.scene;
      const s = typeof raw === 'string' ? JSON.parse(raw) : JSON.parse(new TextDecoder().decode(raw));
      return s.observers.map((o) => {
        let best = 0; let most = -1;
        for (let f = 0; f < s.frames; f += 1) {
          let n = 0;
          for (let k = 0; k < 13; k += 1) if (o.rays[4 * (13 * f + k) + 3] > 0.5) n += 1;
          if (n > most) { most = n; best = f; }
        }
        return best;
      });
    });
    for (let i = 0; i < ids.length; i += 1) {
      await viewer('seek', seeing[i]);
      await page.keyboard.press('o');
      assert.equal(await viewer('view_from_observer'), i);
      assert.equal(await page.inputValue('#view-from'), String(i));
      await settle();
      const image = await shot(`sample-observer-${ids[i]}.png`);
      const { left, right } = skeletonPixels(image.rgba);
      assert.ok(left + right > 80, `the wearer is in observer ${ids[i]}'s view: ${left} + ${right}`);
      let markers = 0;
      for (let p = 0; p < image.rgba.length; p += 4) {
        const [r, g, b] = [image.rgba[p], image.rgba[p + 1], image.rgba[p + 2]];
        if (g > 150 && b < 0.45 * g && r < 1.1 * g) markers += 1; // the gate's yellow → green (not the body's orange)
      }
      assert.ok(markers > 40, `observer ${ids[i]}: ${markers} gate-coloured keypoint pixels`);
    }
    await page.keyboard.press('o');
    assert.equal(await viewer('view_from_observer'), -1);
    await assert.rejects(viewer('set_view_from_observer', ids.length), /no observer/);

    // The timeline plots: a strip per observer and the error over time, under the scrubber;
    // hovering says the values, clicking seeks.
    assert.equal(await page.isVisible('#plots'), true);
    const labels = await app.text('#plot-labels');
    for (const id of ids) assert.match(labels, new RegExp(id));
    assert.match(labels, /error \(cm\) 0–\d+/);
    const canvas = page.locator('#plot-canvas');
    const box = await canvas.boundingBox();
    const track = await page.locator('#scrubber').boundingBox();
    assert.ok(box.x > track.x && box.x + box.width < track.x + track.width + 1, 'the plots span the scrubber');
    await canvas.hover({ position: { x: box.width * 0.4, y: 5 } });
    const hover = await app.text('#plot-hover');
    assert.match(hover, /joints in view/);
    assert.match(hover, /MPJPE \d+\.\d cm/);
    await canvas.click({ position: { x: box.width * 0.25, y: box.height - 10 } });
    const frames = await viewer('frames');
    const clicked = await viewer('frame');
    assert.ok(Math.abs(clicked - 0.25 * (frames - 1)) <= 2, `clicked at a quarter, now at frame ${clicked} of ${frames}`);
    const playhead = await page.locator('#plot-playhead').boundingBox();
    assert.ok(Math.abs(playhead.x - (box.x + box.width * 0.25)) <= 3, `playhead at ${playhead.x}`);
    await page.screenshot({ path: join(OUT, 'app-plots.png') });

    await page.keyboard.press('?');
    assert.equal(await page.evaluate(() => document.getElementById('help-dialog').open), true);
    assert.match(await app.text('#help-dialog'), /follow the wearer/);
    await page.screenshot({ path: join(OUT, 'app-help.png') });
    await page.click('#help-close');
    await page.screenshot({ path: join(OUT, 'app-1280x800.png') });
  });

  test('the 3D view exports as an MP4 (looped frames, session rate; decoded by PyAV) and a PNG; a video export cancels', async () => {
    const { page } = app;
    assert.ok(PYTHON, 'EGOEXO_PYTHON (the tests\' venv, `cargo xtask setup`) decodes the video');
    const viewer = (f, ...args) => page.evaluate(([f, args]) => window.egoexo.viewer[f](...args), [f, args]);
    await viewer('set_view_from_observer', -1);
    await viewer('pause');
    await viewer('set_loop', 100, 159);
    const fps = await viewer('fps');
    const [download] = await Promise.all([
      page.waitForEvent('download', { timeout: 180_000 }),
      page.click('#video-button'),
    ]);
    const path = join(OUT, 'sample-view.mp4');
    await download.saveAs(path);
    assert.match(download.suggestedFilename(), /\.mp4$/);
    // An independent decoder (FFmpeg, through PyAV) reads every frame back.
    const probe = `
import av, json, sys
with av.open(sys.argv[1]) as c:
    s = c.streams.video[0]
    frames = [f.to_ndarray(format="rgb24") for f in c.decode(s)]
    lit = [float((f.max(axis=2) > 80).mean()) for f in frames]
    print(json.dumps({"codec": s.codec_context.name, "frames": len(frames), "width": s.codec_context.width,
                      "height": s.codec_context.height, "rate": float(s.average_rate), "lit": min(lit)}))
`;
    const info = JSON.parse(execFileSync(PYTHON, ['-c', probe, path], { encoding: 'utf8' }));
    assert.equal(info.codec, 'h264');
    assert.equal(info.frames, 60, JSON.stringify(info));
    assert.ok(Math.abs(info.rate - fps) < 0.01, JSON.stringify(info));
    const canvas = await page.evaluate(() => [window.egoexo.viewer.canvas().width, window.egoexo.viewer.canvas().height]);
    assert.deepEqual([info.width, info.height], canvas.map((v) => v & ~1));
    assert.ok(info.lit > 0.002, `every frame shows the scene, not a blank canvas: ${JSON.stringify(info)}`);
    assert.equal(await page.isVisible('#video-progress-row'), false);

    // The whole session, cancelled part-way: no file, no error, the progress bar gone.
    await viewer('clear_loop');
    let downloaded = false;
    page.once('download', () => { downloaded = true; });
    await page.click('#video-button');
    await page.waitForFunction(() => document.getElementById('video-progress').value > 0.02, null, { timeout: 60_000 });
    await page.click('#video-cancel');
    await page.waitForFunction(() => document.getElementById('video-progress-row').hidden, null, { timeout: 30_000 });
    await page.waitForTimeout(500);
    assert.equal(downloaded, false);
    assert.equal(await page.isVisible('#error-panel'), false);

    const [png] = await Promise.all([page.waitForEvent('download'), page.click('#png-button')]);
    const pngPath = join(OUT, 'sample-frame.png');
    await png.saveAs(pngPath);
    const image = decodePng(readFileSync(pngPath));
    assert.deepEqual([image.width, image.height], canvas);
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
