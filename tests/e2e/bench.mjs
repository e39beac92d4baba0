// Runs web/bench.html (served dist/) in headless Chromium and prints the median frames/s.
// Usage: node tests/e2e/bench.mjs [runs]   (EGOEXO_E2E_URL: the served app; `cargo xtask bench-web`)

import { APP_URL, launch } from './browser.mjs';

const runs = Number(process.argv[2] ?? 5);
const browser = await launch();
try {
  const page = await browser.newPage();
  page.on('console', (m) => {
    if (m.type() === 'error') console.error(`bench page: ${m.text()}`);
  });
  await page.goto(new URL(`bench.html?runs=${runs}`, APP_URL).href);
  await page.waitForFunction(() => document.body.dataset.state !== 'running', null, { timeout: 1_800_000, polling: 250 });
  const log = await page.locator('#log').innerText();
  console.error(log);
  const state = await page.evaluate(() => document.body.dataset.state);
  if (state !== 'done') throw new Error(`the bench failed: ${await page.evaluate(() => document.body.dataset.error)}`);
  const result = await page.evaluate(() => document.body.dataset.result);
  console.log(`BENCH ${result}`);
} finally {
  await browser.close();
}
