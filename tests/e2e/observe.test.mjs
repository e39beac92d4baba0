// The observer page end to end: a camera in the room is a browser page. `egoexo walk` films a
// wearer wandering in front of a tripod (`--static-cameras --video 480 --y4m`); a Chromium
// whose fake camera plays that film opens the Live panel's camera link (`/observe.html`, read
// from the panel's QR code as a phone would),
// joins the room as a static camera and streams the keypoints its detector finds, while
// `egoexo live replay --no-observers` streams the wearer's glasses. The watching page receives
// the camera's keypoints, lists it, registers it in 6 DoF and fuses its rays, and tells the
// camera where it sees the wearer, which the camera then crops.

import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readdirSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { after, before, describe, test } from 'node:test';

import jsQR from 'jsqr';
import { PNG } from 'pngjs';

import { APP_URL, EGOEXO, egoexo, launch, openApp } from './browser.mjs';

const dir = mkdtempSync(join(tmpdir(), 'egoexo-observe-'));
let viewerBrowser;
let cameraBrowser;
let film;
before(async () => {
  // 24 s of a wearer wandering before one tripod, filmed at 480 × 480 (a pinhole of the
  // simulator's field of view, written beside the film). Registration needs about 5 s of views
  // on an idle machine; on a loaded one (CI runs two browser files at once) the page detects
  // fewer frames a second and the replay joins later into the walk, and 16 s once left 9 s of
  // views, too few.
  execFileSync(EGOEXO, [
    'walk', '--seconds', '24', '--wander', '--observers', '1', '--static-cameras', '--video', '480',
    '--y4m', join(dir, 'cameras'), '-o', join(dir, 'walk.egoexo'), '--seed', '5',
  ], { stdio: ['ignore', 'ignore', 'inherit'] });
  const name = readdirSync(join(dir, 'cameras')).find((f) => f.endsWith('.y4m'));
  film = {
    y4m: join(dir, 'cameras', name),
    camera: JSON.parse(readFileSync(join(dir, 'cameras', name.replace(/\.y4m$/, '.camera.json')), 'utf8')),
  };
  viewerBrowser = await launch();
  cameraBrowser = await launch([
    '--use-fake-device-for-media-stream',
    '--use-fake-ui-for-media-stream',
    `--use-file-for-fake-video-capture=${film.y4m}`,
  ]);
});
after(async () => {
  await cameraBrowser?.close();
  await viewerBrowser?.close();
  rmSync(dir, { recursive: true, force: true });
});

const live = (app) => app.page.evaluate(() => {
  const l = window.egoexo.live.snapshot();
  return { frames: l.frames, devices: l.devices, lastFrame: l.lastFrame };
});

async function waitFor(what, read, predicate, timeout = 60_000) {
  const start = Date.now();
  for (;;) {
    const now = await read();
    if (predicate(now)) return now;
    if (Date.now() - start > timeout) throw new Error(`waiting for ${what}: ${JSON.stringify(now).slice(0, 2000)}`);
    await new Promise((r) => setTimeout(r, 250));
  }
}

describe('observer page', () => {
  test('a browser camera joins by the camera link, detects the wearer and is registered', async (t) => {
    const app = await openApp(viewerBrowser, '?backend=webgl2');
    assert.equal(await app.waitState(['idle', 'error']), 'idle', await app.text('#error-message'));
    await app.page.getByRole('button', { name: 'Go live' }).click();
    await app.page.waitForSelector('#live-room[data-code]');
    const code = await app.page.getAttribute('#live-room', 'data-code');
    const link = new URL(await app.page.getByLabel('camera page').inputValue());
    assert.equal(link.pathname, '/observe.html');
    // A phone scans the QR code beside the link: it holds the same link.
    const qr = PNG.sync.read(await app.page.locator('#live-facts figure.qr svg').screenshot());
    const scanned = jsQR(new Uint8ClampedArray(qr.data), qr.width, qr.height);
    assert.ok(scanned, `a readable QR code (${qr.width} × ${qr.height} px)`);
    assert.equal(scanned.data, link.href);
    await app.waitState('live');

    // The camera page from the link, told the film's field of view.
    link.search = `?device=tripod&fov=${film.camera.horizontal_fov_deg.toFixed(3)}`;
    const camera = await openApp(cameraBrowser, '', { path: link.href.slice(APP_URL.length) });
    await camera.waitState(['ready', 'error', 'unsupported'], 60_000);
    assert.equal(await camera.text('#link-label'), `room ${link.hash.slice(6, 12)}…`);
    await camera.page.getByRole('button', { name: 'Start observing' }).click();
    assert.equal(await camera.waitState(['observing', 'error'], 60_000), 'observing', await camera.text('#error-message'));
    // The film started with the camera's first frame: the wearer's glasses keep time with it
    // (the replay streams from where the walk is by the time it is connected).
    const firstFrameMs = Number(await camera.page.evaluate(() => document.body.dataset.firstFrameMs));
    const replay = egoexo(['live', 'replay', join(dir, 'walk.egoexo'), '--url', APP_URL, '--room', code,
      '--no-observers', '--start-at-unix-ms', firstFrameMs.toFixed(3),
      '--jitter-ms', '0', '--clock-spread-s', '0', '--drift-ppm', '0']);
    let replayEnded = false;
    replay.then(() => { replayEnded = true; }, () => { replayEnded = true; });

    // The camera page finds the wearer and draws them.
    const found = await waitFor('detections on the camera page', () => camera.page.evaluate(() => Number(document.body.dataset.detections)), (n) => n >= 30);
    t.diagnostic(`camera page: ${await camera.text('#detect-rate')}; region ${await camera.text('#crop-source')}`);
    assert.ok(found >= 30);
    assert.match(await camera.text('#camera-info'), /480×480, \d+(\.\d+)?° wide/);
    // The screen is kept on while it observes (a phone on a stand would lock and stop its camera).
    assert.equal(await camera.page.evaluate(() => document.body.dataset.screen), 'held', await camera.text('#screen-state'));
    assert.equal(await camera.text('#screen-state'), 'kept on while observing');

    // The watching page lists it, with its keypoints' rate, as a camera being registered.
    const listed = await waitFor('the camera listed', () => live(app), (l) => l.devices.some((d) => d.device === 'tripod' && d.rates_hz.some(([s, hz]) => s === 'keypoints' && hz > 3)));
    const tripod = listed.devices.find((d) => d.device === 'tripod');
    t.diagnostic(`tripod on the relay: ${JSON.stringify(tripod.rates_hz)}, latency ${(tripod.latency_ns / 1e6).toFixed(0)} ms`);
    const registering = await waitFor('the camera registering', () => live(app), (l) => (l.lastFrame?.observer_worlds ?? []).some((o) => o.observer === 'tripod'));
    t.diagnostic(JSON.stringify(registering.lastFrame.observer_worlds));
    // The camera page hears where it stands through the relay.
    await camera.page.waitForFunction(() => ['registering', 'registered'].includes(document.body.dataset.registration), null, { timeout: 15_000 });
    assert.match(await camera.text('#registration'), /^registering|^registered/);

    // Registered from its views, placed, then fused — where the camera page detects often enough
    // for that: 10 detections a second (docs/live-protocol.md measured 10–14/s on an idle
    // machine). Below that (6–9/s in a slow hour, with the viewer's reconstruction beside it) the
    // views of one camera have left its place uncertain (1σ 16 cm against the 12 cm limit) or
    // wrong (118 cm off, 16 % of its distance): issue 41 keeps the detector's speed (≥ 15/s) and
    // that registration open, so there the checks run and report as a todo.
    const rate = Number((await camera.text('#detect-rate')).match(/^(\d+(?:\.\d+)?) frames\/s/)?.[1] ?? 0);
    const slow = rate < 10 && `the camera page detects ${rate} frames/s here, under the 10/s its registration needs (issue 41)`;
    await t.test('registered from its views, placed within a tenth of its distance to the wearer, then its rays fused', { todo: slow }, async (sub) => {
      // Until the replay ends: after it, the wearer is gone and nothing more is learnt.
      const registered = await waitFor('the camera registered or the replay ended', async () => ({ ...(await live(app)), replayEnded }),
        (l) => l.replayEnded || (l.lastFrame?.observer_worlds ?? []).some((o) => o.observer === 'tripod' && o.state === 'registered'), 90_000);
      const world = registered.lastFrame.observer_worlds.find((o) => o.observer === 'tripod');
      assert.equal(world.state, 'registered', `the replay ended before the camera was registered: ${JSON.stringify(world)}`);
      sub.diagnostic(`registered after ${world.registered_after_s?.toFixed(1)} s of views: ${world.message}`);
      // The camera page hears it through the relay and says so.
      await camera.page.waitForFunction(() => document.body.dataset.registration === 'registered', null, { timeout: 15_000 });
      assert.match(await camera.text('#registration'), /^registered (after|over) /);
      // Where it stands, then its rays fused. (Until 2026-12-07 this was a TODO: the camera was
      // placed 26–70 cm off and fused in 2 of 6 runs. The film's start was taken as the first
      // frame the page saw, up to a second after the camera's first, so the wearer's replay ran
      // late against the film; from the capture time less the media time it is the camera's
      // first frame, and 6 of 6 runs placed it 9–37 cm off and fused it.)
      // The filmed camera's true place (its registration maps the page's device frame, the
      // camera frame, into the wearer's world), within a tenth of its distance to the wearer —
      // one camera's depth comes from the size of the body it sees, and the detector's
      // keypoints of a rendered body measure it to a few per cent (docs/live-protocol.md).
      const truth = film.camera.t_world_camera.translation;
      const off = Math.hypot(...world.translation_m.map((v, i) => v - truth[i]));
      const distance = film.camera.mean_distance_to_wearer_m;
      sub.diagnostic(`the camera placed ${(off * 100).toFixed(1)} cm from where it filmed, ${(100 * off / distance).toFixed(1)} % of its ${distance.toFixed(1)} m to the wearer`);
      assert.ok(off < 0.1 * distance, `placed at ${world.translation_m}, filmed from ${truth}, ${distance} m from the wearer`);
      // Until the replay ends: after it, no frame is reconstructed.
      const fused = await waitFor('its rays fused or the replay ended', async () => ({ l: await live(app), ended: replayEnded }),
        ({ l, ended }) => ended || (l.lastFrame?.exo_observers ?? []).includes('tripod'), 60_000);
      assert.ok((fused.l.lastFrame?.exo_observers ?? []).includes('tripod'), `the replay ended before its rays were fused: ${JSON.stringify(fused.l.lastFrame)}`);
      // Placed, the camera hears where the watching page sees the wearer in its image (the
      // ego signals' region) and crops there.
      await camera.page.waitForFunction(() => Number(document.body.dataset.regions) > 0 && document.body.dataset.cropSource === 'ego signals', null, { timeout: 15_000 })
        .catch(async (e) => assert.fail(`the camera page never cropped in a wearer region (${await camera.page.evaluate(() => JSON.stringify(document.body.dataset))}): ${e.message}`));
      sub.diagnostic(`camera page: ${await camera.page.evaluate(() => document.body.dataset.regions)} wearer regions heard, region: ${await camera.text('#crop-source')}`);
    });
    await replay;
    // Stop lets the screen sleep again.
    await camera.page.getByRole('button', { name: 'Stop' }).click();
    assert.equal(await camera.waitState(['ready', 'error']), 'ready', await camera.text('#error-message'));
    assert.equal(await camera.page.evaluate(() => document.body.dataset.screen), 'off');
    assert.deepEqual(camera.errors, []);
    assert.deepEqual(app.errors, []);
    await camera.close();
    await app.close();
  });
});
