// The bench page: the sample through the app's worker, N timed reconstructions, medians.

const params = new URLSearchParams(location.search);
const runs = Math.max(1, Number(params.get('runs') ?? 5));
const log = document.getElementById('log');
const lines = [];
const say = (line) => {
  lines.push(line);
  log.textContent = lines.join('\n');
};

const worker = new Worker(new URL('worker.js', import.meta.url), { type: 'module' });
let pending = null;
worker.onmessage = ({ data }) => {
  if (data.type === 'progress' || data.type === 'status' || data.type === 'models') return;
  const settle = pending;
  pending = null;
  if (data.type === 'error' || data.type === 'panic') settle?.reject(new Error(`${data.stage ?? 'panic'}: ${data.message}`));
  else settle?.resolve(data);
};
worker.onerror = (e) => pending?.reject(new Error(e.message || 'worker failed'));
const request = (message, transfer = []) => new Promise((resolve, reject) => {
  pending = { resolve, reject };
  worker.postMessage(message, transfer);
});

const median = (xs) => {
  const s = [...xs].sort((a, b) => a - b);
  const m = s.length >> 1;
  return s.length % 2 ? s[m] : (s[m - 1] + s[m]) / 2;
};

async function main() {
  const list = await (await fetch('samples/samples.json')).json();
  const sample = list.samples[0];
  const bytes = new Uint8Array(await (await fetch(`samples/${sample.file}`)).arrayBuffer());
  const { summary } = await request({ type: 'open', input: { kind: 'archive', name: sample.file, bytes } }, [bytes.buffer]);
  const frames = summary.frames;
  say(`${sample.file}: ${frames} frames, ${summary.observers.length} observers, ${summary.tracking_points}-point tracking`);
  const time = async (overlay) => (await request({ type: 'reconstruct', overlay })).elapsedMs;
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
