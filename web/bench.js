// The bench page: the sample through the app's worker, N timed reconstructions, medians.
// Messages go through the page's WorkerClient, as in the app.

import initViewer, { Viewer, WorkerClient } from './pkg/egoexo_viewer.js';

const params = new URLSearchParams(location.search);
const runs = Math.max(1, Number(params.get('runs') ?? 5));
const log = document.getElementById('log');
const lines = [];
const say = (line) => {
  lines.push(line);
  log.textContent = lines.join('\n');
};

await initViewer();

// A worker of the app with a pool of `workers` workers (`?workers=N` on its URL), and
// `request(send)`: sends a request (`send(client)`) and waits for its answer.
function appWorker(workers) {
  const url = new URL('worker.js', import.meta.url);
  url.searchParams.set('workers', String(workers));
  const worker = new Worker(url, { type: 'module' });
  const client = new WorkerClient(worker);
  // The answer to the one request in flight: its result, or its error.
  const ANSWERS = new Set(['imported', 'reconstructed', 'exported', 'error', 'panic']);
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
  const request = (send) => new Promise((resolve, reject) => {
    pending = { resolve, reject };
    send(client);
  });
  return { request, terminate: () => worker.terminate() };
}

// The measurements in one worker (`?workers=` on the page overrides it), as the goals are set.
const one = appWorker(Number(params.get('workers') ?? 1));
const request = one.request;
// The same whole job shared by a pool of `poolSize` workers, for the scaling.
const poolSize = Math.max(2, Number(params.get('pool') ?? 2));

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
  const { summary } = await request((c) => c.open_archive(sample.file, bytes.slice()));
  const frames = summary.frames;
  say(`${sample.file}: ${frames} frames, ${summary.observers.length} observers, ${summary.tracking_points}-point tracking`);
  // Milliseconds from asking to the scene's arrival (the worker cannot read a clock).
  const time = async (overlay) => {
    const started = performance.now();
    await request((c) => c.reconstruct(overlay));
    return performance.now() - started;
  };
  say(`warm-up: ${(await time(false)).toFixed(0)} ms`);
  // The pool: its own coordinator and helpers, warmed up on the same sample (the helpers
  // start once the coordinator's models are loaded; two jobs make sure they are ready).
  const pool = appWorker(poolSize);
  await pool.request((c) => c.open_archive(sample.file, bytes.slice()));
  for (let i = 0; i < 2; i += 1) await pool.request((c) => c.reconstruct(true));
  const poolJob = [];
  const poolShares = [];
  const egoExo = [];
  const appJob = [];
  // Per run, the worker's time per stage (its summary's `timings`, taken with the clock the
  // glue passes in) of a fresh open (import, align) and the whole job, plus an npz export
  // timed here from request to file.
  const stageRuns = [];
  let scene = null;
  for (let i = 0; i < runs; i += 1) {
    egoExo.push(await time(false));
    await request((c) => c.open_archive(sample.file, bytes.slice()));
    const started = performance.now();
    const { summary: job, scene: jobScene } = await request((c) => c.reconstruct(true));
    scene = jobScene;
    appJob.push(performance.now() - started);
    const exportStarted = performance.now();
    await request((c) => c.export('npz'));
    const stages = Object.fromEntries((job.timings ?? []).map((t) => [t.stage, t.ms]));
    stages.export = performance.now() - exportStarted;
    stageRuns.push(stages);
    await pool.request((c) => c.open_archive(sample.file, bytes.slice()));
    const poolStarted = performance.now();
    const { summary: pooled } = await pool.request((c) => c.reconstruct(true));
    poolJob.push(performance.now() - poolStarted);
    poolShares.push(pooled.pool ? pooled.pool.helper_chunks / pooled.pool.chunks : 0);
    say(`run ${i + 1}/${runs}: ego-exo ${egoExo[i].toFixed(0)} ms, whole job ${appJob[i].toFixed(0)} ms, `
      + `with ${poolSize} workers ${poolJob[i].toFixed(0)} ms (helpers computed ${(100 * poolShares[i]).toFixed(0)} % of the chunks)`);
  }
  const stageNames = [...new Set(stageRuns.flatMap((r) => Object.keys(r)))];
  const stages = stageNames.map((stage) => ({ stage, ms: median(stageRuns.map((r) => r[stage] ?? 0)) }));
  for (const { stage, ms } of stages) say(`  ${stage.padEnd(14)} ${ms.toFixed(2).padStart(9)} ms`);
  const result = {
    sample: sample.file,
    frames,
    runs,
    median_ms: median(egoExo),
    median_fps: frames / (median(egoExo) / 1000),
    median_app_ms: median(appJob),
    median_app_fps: frames / (median(appJob) / 1000),
    cores: navigator.hardwareConcurrency,
    stages,
    pool_workers: poolSize,
    median_pool_ms: median(poolJob),
    median_pool_fps: frames / (median(poolJob) / 1000),
    pool_speedup: median(appJob) / median(poolJob),
    median_helper_share: median(poolShares),
  };
  pool.terminate();
  say(`median ego-exo: ${result.median_fps.toFixed(0)} frames/s (${result.median_ms.toFixed(0)} ms)`);
  say(`median whole job: ${result.median_app_fps.toFixed(0)} frames/s (${result.median_app_ms.toFixed(0)} ms)`);
  say(`median whole job, ${poolSize} workers: ${result.median_pool_fps.toFixed(0)} frames/s (${result.median_pool_ms.toFixed(0)} ms), `
    + `${result.pool_speedup.toFixed(2)}× one worker`);
  result.render = await renderBench(scene, Math.max(30, 20 * runs));
  result.networks = await compareNetworks(summary.tracking_points, Math.max(10, 4 * runs));
  document.body.dataset.result = JSON.stringify(result);
  document.body.dataset.state = 'done';
}

// The 3D view's frame time for the sample's scene on a 960×540 canvas: bodies of capsules
// against stick figures, alternating, `frames` frames each (the viewer draws a frame, then the
// canvas is read into an ImageBitmap, so the GPU's work is in the time).
async function renderBench(sceneBytes, frames) {
  const canvas = document.createElement('canvas');
  canvas.width = 960;
  canvas.height = 540;
  canvas.style.cssText = 'width: 960px; height: 540px; position: absolute; left: -10000px;';
  document.body.append(canvas);
  const viewer = await Viewer.create(canvas, params.get('backend') ?? 'auto');
  viewer.set_scene_json(sceneBytes);
  viewer.pause();
  const drawn = viewer.canvas();
  const times = { body: [], stick: [] };
  const total = viewer.frames();
  for (let i = 0; i < 2 * frames; i += 1) {
    const mode = i % 2 === 0 ? 'body' : 'stick';
    viewer.set_show_body(mode === 'body');
    viewer.seek((i * 7) % total);
    const started = performance.now();
    viewer.render_now();
    (await createImageBitmap(drawn)).close();
    times[mode].push(performance.now() - started);
  }
  const result = {
    backend: viewer.backend(),
    width: drawn.width,
    height: drawn.height,
    frames,
    body_ms: median(times.body.slice(2)),
    stick_ms: median(times.stick.slice(2)),
  };
  viewer.free();
  drawn.remove();
  say(`3D view (${result.backend}, ${result.width}×${result.height}): body ${result.body_ms.toFixed(2)} ms a frame, `
    + `stick figure ${result.stick_ms.toFixed(2)} ms (median of ${frames} each)`);
  return result;
}

// The engines side by side on the same networks and inputs, in a worker of their own
// (web/bench-networks.js).
async function compareNetworks(points, networkRuns) {
  say(`networks (${points}-point), ${networkRuns} alternating runs each:`);
  const bench = new Worker(new URL('bench-networks.js', import.meta.url), { type: 'module' });
  const answer = await new Promise((resolve, reject) => {
    bench.onmessage = ({ data }) => resolve(data);
    bench.onerror = (e) => reject(new Error(e.message || 'the network bench worker failed'));
    bench.postMessage({ points, runs: networkRuns });
  });
  bench.terminate();
  if (!answer.ok) throw new Error(`network bench: ${answer.error}`);
  const { result } = answer;
  if (result.ort_missing) say(`  onnxruntime-web not available (${result.ort_missing}): tract alone`);
  const f = (v, d = 2) => (v == null ? '-' : v.toFixed(d));
  for (const n of result.networks) {
    say(`  ${n.network.padEnd(7)} tract ${f(n.tract_ms, 3)} ms, onnxruntime-web ${f(n.ort_ms, 3)} ms, ratio ${f(n.ratio)}, `
      + `max |diff| ${n.max_abs_diff == null ? '-' : n.max_abs_diff.toExponential(1)}, load ${f(n.tract_load_ms, 0)} / ${f(n.ort_load_ms, 0)} ms, `
      + `${f(n.flops / 1e6)} MFLOP, ${f(n.tract_gflops)} of ${f(n.attainable_gflops)} GFLOP/s attainable (${n.probe})`);
  }
  return result;
}

main().catch((error) => {
  say(`failed: ${error.message}`);
  document.body.dataset.error = error.message;
  document.body.dataset.state = 'failed';
});
