// Shared by the end-to-end tests and the bench: Debian's Chromium through playwright-core,
// the app's URL (served by `cargo xtask`), console capture and pixel checks.

import { spawn } from 'node:child_process';
import { mkdirSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { after, before } from 'node:test';
import { chromium } from 'playwright-core';
import { PNG } from 'pngjs';

export const APP_URL = process.env.EGOEXO_E2E_URL ?? 'http://127.0.0.1:8080/';
export const OUT = process.env.EGOEXO_E2E_OUT ?? 'target/e2e';
// The `egoexo` CLI the suite runs (set by `cargo xtask`).
export const EGOEXO = process.env.EGOEXO_BIN ?? 'egoexo';
mkdirSync(OUT, { recursive: true });

// A closed network and a root user (shared/notes/toolchain.md); WebGPU through SwiftShader.
const ARGS = [
  '--no-sandbox',
  '--disable-quic',
  '--no-first-run',
  '--disable-background-networking',
  '--disable-component-update',
  '--disable-sync',
  '--disable-default-apps',
  '--disable-extensions',
  '--enable-unsafe-webgpu',
  '--enable-unsafe-swiftshader',
];

// `extraArgs`: more Chromium switches (e.g. a fake camera playing a file).
export function launch(extraArgs = []) {
  return chromium.launch({
    executablePath: process.env.EGOEXO_CHROMIUM ?? '/usr/bin/chromium',
    headless: true,
    args: [...ARGS, ...extraArgs],
  });
}

// One Chromium for a test file: launched before its first test, closed after its last. Returns
// a getter, since the browser exists only once the `before` hook has run.
export function chromiumForFile(extraArgs = []) {
  let browser;
  before(async () => {
    browser = await launch(extraArgs);
  });
  after(async () => {
    await browser?.close();
  });
  return () => browser;
}

// Opens the app in a fresh context (its own Cache API storage) and records every console
// error, uncaught exception and failed worker of the page.
// `setup(context)` runs before the page loads (e.g. to install request routes).
// The page asks for reduced motion (`prefers-reduced-motion: reduce`), as a user can: a
// reconstruction then opens paused, so SwiftShader does not draw a playing view while a test
// reads something else — that kept Chromium's GPU process busy on 1.7 cores
// (docs/performance.md). Tests of playback press Play; `reducedMotion: 'no-preference'`
// opens the page as most users see it.
export async function openApp(browser, query = '', { path = '', setup, reducedMotion = 'reduce' } = {}) {
  const context = await browser.newContext({ viewport: { width: 1280, height: 800 }, acceptDownloads: true, reducedMotion });
  await setup?.(context);
  const page = await context.newPage();
  const errors = [];
  page.on('console', (m) => {
    if (m.type() === 'error') errors.push(`console: ${m.text()}`);
  });
  page.on('pageerror', (e) => errors.push(`uncaught: ${e.message}`));
  page.on('worker', (w) => {
    w.on('console', (m) => {
      if (m.type() === 'error') errors.push(`worker console: ${m.text()}`);
    });
  });
  await page.goto(new URL(path + query, APP_URL).href);
  const app = {
    page,
    context,
    errors,
    // Waits until <body data-state> is one of `states`.
    // On a timeout, says where the app stood (state and progress line) and what it logged.
    async waitState(states, timeout = 600_000) {
      const list = [].concat(states);
      try {
        await page.waitForFunction((l) => l.includes(document.body.dataset.state), list, { timeout, polling: 100 });
      } catch (error) {
        const where = await page
          .evaluate(() => `state ${document.body.dataset.state}, progress "${document.getElementById('progress-text')?.textContent}"`)
          .catch(() => 'page gone');
        throw new Error(`waiting for state ${list.join('/')}: ${error.message} (${where}; errors: ${JSON.stringify(errors)})`);
      }
      return page.evaluate(() => document.body.dataset.state);
    },
    text: (selector) => page.locator(selector).innerText(),
    async close() {
      await context.close();
    },
  };
  return app;
}

export function decodePng(buffer) {
  const png = PNG.sync.read(buffer);
  return { width: png.width, height: png.height, rgba: png.data };
}

export function savePng(name, width, height, rgba) {
  const png = new PNG({ width, height });
  png.data = Buffer.from(rgba);
  const path = join(OUT, name);
  writeFileSync(path, PNG.sync.write(png));
  return path;
}

// Pixels in the skeleton's colours: egoexo-viewer's palette draws the reconstruction's left
// side saturated blue [0.20, 0.52, 1.00] and its right side saturated orange
// [1.00, 0.45, 0.12], lit and shaded (channel ratios stay). Nothing else in the scene is that
// saturated in those hues: frustums are cyan and magenta, the device trails and the
// ground-truth ghost pale, the grid grey; only observer rays (red → yellow → green by gate)
// pass through orange, so pixel checks of the right side turn the rays off.
export function skeletonPixels(rgba) {
  let left = 0;
  let right = 0;
  for (let i = 0; i < rgba.length; i += 4) {
    const r = rgba[i];
    const g = rgba[i + 1];
    const b = rgba[i + 2];
    if (b >= 140 && r <= 0.4 * b && g <= 0.65 * b && g >= r) left += 1;
    else if (r >= 140 && g <= 0.58 * r && g >= 0.28 * r && b <= 0.3 * r) right += 1;
  }
  return { left, right };
}

// Runs `egoexo args…` in the background; resolves with its standard output once it exits 0,
// rejects with its standard error otherwise.
export function egoexo(args) {
  return new Promise((resolve, reject) => {
    const child = spawn(EGOEXO, args, { stdio: ['ignore', 'pipe', 'pipe'] });
    let out = '';
    let err = '';
    child.stdout.on('data', (d) => (out += d));
    child.stderr.on('data', (d) => (err += d));
    child.on('error', reject);
    child.on('exit', (code) => (code === 0 ? resolve(out) : reject(new Error(`egoexo ${args.join(' ')} exited ${code}:\n${err}`))));
  });
}
