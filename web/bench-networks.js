// The bench page's engine comparison, in its own module Web Worker: each shipped network of
// one tracking mode run on the same deterministic inputs by tract (our worker's wasm,
// `NetworkBench`) and by onnxruntime-web (its wasm backend, SIMD, one thread), alternating
// runs; per network the median ms per window of each, their ratio, the largest output
// difference, the load + optimise time of each, the network's FLOPs per window, and the
// attainable rate of a plain matrix product of its dominant shape through tract. Timings are
// taken here; the wasm reads no clock.

import init, { NetworkBench } from './pkg/egoexo_web_worker.js';

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  const m = s.length >> 1;
  return s.length % 2 ? s[m] : (s[m - 1] + s[m]) / 2;
};

const fetchBytes = async (url) => {
  const response = await fetch(url);
  if (!response.ok) throw new Error(`${url}: HTTP ${response.status}`);
  return new Uint8Array(await response.arrayBuffer());
};

// onnxruntime-web, when dist/ carries it (vendor/, copied from tests/node_modules by the
// build); `null` otherwise, and the table has tract alone.
async function loadOrt() {
  try {
    const ort = await import('./vendor/onnxruntime-web/ort.wasm.min.mjs');
    ort.env.wasm.numThreads = 1;
    ort.env.wasm.proxy = false;
    ort.env.wasm.wasmPaths = new URL('vendor/onnxruntime-web/', import.meta.url).href;
    return ort;
  } catch (error) {
    return { missing: String(error?.message ?? error) };
  }
}

async function compare({ points, runs }) {
  await init();
  const modelsUrl = new URL('models/', import.meta.url);
  const manifestBytes = await fetchBytes(new URL('manifest.json', modelsUrl));
  const manifest = JSON.parse(new TextDecoder().decode(manifestBytes));
  const tracking = points === 3 ? 'three_point' : 'one_point';
  const set = manifest.model_sets.find((s) => s.tracking === tracking && s.lookahead == null);
  if (!set) throw new Error(`the manifest has no offline ${points}-point model set`);
  const ort = await loadOrt();
  const haveOrt = !ort.missing;
  const networks = [];
  // `fusion_ego_only` (the fusion with every observer masked) is in sets exported since it
  // existed; older sets have three networks.
  for (const network of ['egonet', 'gate', 'fusion', 'fusion_ego_only'].filter((n) => set[n])) {
    const bytes = await fetchBytes(new URL(set[network].file, modelsUrl));
    let started = performance.now();
    const tract = new NetworkBench(manifestBytes, points, network, bytes.slice());
    const tractLoadMs = performance.now() - started;
    const row = { network, tract_load_ms: tractLoadMs };
    const tractOut = tract.run();
    let session = null;
    let feeds = null;
    if (haveOrt) {
      started = performance.now();
      session = await ort.InferenceSession.create(bytes, { executionProviders: ['wasm'], graphOptimizationLevel: 'all' });
      row.ort_load_ms = performance.now() - started;
      feeds = {};
      for (let i = 0; i < tract.inputCount(); i += 1) {
        feeds[tract.inputName(i)] = new ort.Tensor('float32', tract.input(i), Array.from(tract.inputShape(i)));
      }
      const out = await session.run(feeds);
      let at = 0;
      let diff = 0;
      for (const name of tract.outputNames()) {
        for (const v of out[name].data) diff = Math.max(diff, Math.abs(v - tractOut[at++]));
      }
      if (at !== tractOut.length) throw new Error(`${network}: onnxruntime-web gave ${at} outputs, tract ${tractOut.length}`);
      row.max_abs_diff = diff;
    }
    // Alternating samples after the warm-up above, so that both see the same machine state.
    // A worker's clock is coarse (0.1 ms here), so each sample is a batch of runs lasting a
    // few milliseconds, and its time per run is the batch's over its size.
    started = performance.now();
    tract.run();
    const batch = Math.min(50, Math.max(1, Math.ceil(3 / Math.max(performance.now() - started, 0.05))));
    row.batch = batch;
    const tractMs = [];
    const ortMs = [];
    for (let r = 0; r < runs; r += 1) {
      started = performance.now();
      for (let b = 0; b < batch; b += 1) tract.run();
      tractMs.push((performance.now() - started) / batch);
      if (session) {
        started = performance.now();
        for (let b = 0; b < batch; b += 1) await session.run(feeds);
        ortMs.push((performance.now() - started) / batch);
      }
    }
    row.tract_ms = median(tractMs);
    if (session) {
      row.ort_ms = median(ortMs);
      row.ratio = row.tract_ms / row.ort_ms;
      await session.release();
    }
    tract.analyse();
    row.flops = tract.flops();
    row.probe = tract.probeShape();
    started = performance.now();
    tract.runProbe();
    const probeBatch = Math.min(200, Math.max(1, Math.ceil(3 / Math.max(performance.now() - started, 0.02))));
    const probeMs = [];
    for (let r = 0; r < runs; r += 1) {
      started = performance.now();
      for (let b = 0; b < probeBatch; b += 1) tract.runProbe();
      probeMs.push((performance.now() - started) / probeBatch);
    }
    row.attainable_gflops = tract.probeFlops() / (median(probeMs) * 1e6);
    row.tract_gflops = row.flops / (row.tract_ms * 1e6);
    if (session) row.ort_gflops = row.flops / (row.ort_ms * 1e6);
    tract.free();
    networks.push(row);
  }
  return { points, runs, networks, ort: haveOrt ? 'onnxruntime-web (wasm, SIMD, 1 thread)' : null, ort_missing: ort.missing ?? null };
}

self.onmessage = async ({ data }) => {
  try {
    self.postMessage({ ok: true, result: await compare(data) });
  } catch (error) {
    self.postMessage({ ok: false, error: String(error?.message ?? error) });
  }
};
