// The bench page: the sample through the app's worker, N timed reconstructions, medians.
// Messages go through the page's WorkerClient, as in the app.

import initViewer, { WorkerClient } from './pkg/egoexo_viewer.js';

const params = new URLSearchParams(location.search);
const runs = Math.max(1, Number(params.get('runs') ?? 5));
const log = document.getElementById('log');
const lines = [];
const say = (line) => {
  lines.push(line);
  log.textContent = lines.join('\n');
};

await initViewer();
const worker = new Worker(new URL('worker.js', import.meta.url), { type: 'module' });
const client = new WorkerClient(worker);
// The answer to the one request in flight: its result, or its error.
const ANSWERS = new Set(['imported', 'reconstructed', 'error', 'panic']);
let pending = null;
worker.onmessage = ({ data }) => {
  const event = client.receive(data);
  if (!event || !ANSWERS.has(event.type)) return;
  const settle = pending;
  pending = null;
  if (event.type === 'error' || event.type === 'panic') settle?.reject(new Error(`${event.stage ?? 'panic'}: ${event.message}`));
  else settle?.resolve(event);
};
worker.onerror = (e) => pending?.reject(new Error(e.message || 'worker failed'));
// Sends a request (`send(client)`) and waits for its answer.
const request = (send) => new Promise((resolve, reject) => {
  pending = { resolve, reject };
  send(client);
});

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  const m = s.length >> 1;
  return s.length % 2 ? s[m] : (s[m - 1] + s[m]) / 2;
};

async function main() {
  const samples = new URL('samples/samples.json', import.meta.url);
  const list = await (await fetch(samples)).json();
  const sample = list.samples[0];
  const bytes = new Uint8Array(await (await fetch(new URL(sample.file, samples))).arrayBuffer());
  const { summary } = await request((c) => c.open_archive(sample.file, bytes));
  const frames = summary.frames;
  say(`${sample.file}: ${frames} frames, ${summary.observers.length} observers, ${summary.tracking_points}-point tracking`);
  // Milliseconds from asking to the scene's arrival (the worker cannot read a clock).
  const time = async (overlay) => {
    const started = performance.now();
    await request((c) => c.reconstruct(overlay));
    return performance.now() - started;
  };
  say(`warm-up: ${(await time(false)).toFixed(0)} ms`);
  const egoExo = [];
  const appJob = [];
  for (let i = 0; i < runs; i += 1) {
    egoExo.push(await time(false));
    appJob.push(await time(true));
    say(`run ${i + 1}/${runs}: ego-exo ${egoExo[i].toFixed(0)} ms, whole job ${appJob[i].toFixed(0)} ms`);
  }
  const result = {
    sample: sample.file,
    frames,
    runs,
    median_ms: median(egoExo),
    median_fps: frames / (median(egoExo) / 1000),
    median_app_ms: median(appJob),
    median_app_fps: frames / (median(appJob) / 1000),
    cores: navigator.hardwareConcurrency,
  };
  say(`median ego-exo: ${result.median_fps.toFixed(0)} frames/s (${result.median_ms.toFixed(0)} ms)`);
  say(`median whole job: ${result.median_app_fps.toFixed(0)} frames/s (${result.median_app_ms.toFixed(0)} ms)`);
  document.body.dataset.result = JSON.stringify(result);
  document.body.dataset.state = 'done';
}

main().catch((error) => {
  say(`failed: ${error.message}`);
  document.body.dataset.error = error.message;
  document.body.dataset.state = 'failed';
});
