// The module Web Worker. Everything it does — reading the page's requests, fetching and
// caching the models, importing, reconstructing, exporting, answering with events — is Rust
// (`WorkerApp` in pkg/egoexo_web_worker.js; the protocol is docs/worker-protocol.md). This
// file only hands the messages over, and spawns the pool's helper workers when the Rust side
// asks (wasm spawns nothing itself).
//
// The page's worker (the coordinator) shares each reconstruction with `workers − 1` helpers:
// the same script, started as nested workers named `egoexo-helper-<i>`. `workers` is the
// worker URL's `?workers=N` (the page passes its own on), else `navigator.hardwareConcurrency`,
// at most MAX_WORKERS; 1 turns the pool off.

import init, { WorkerApp } from './pkg/egoexo_web_worker.js';

/// Most workers in a pool: each holds the networks and a copy of the aligned session.
const MAX_WORKERS = 4;

const early = [];
let app = null;

// Assigned synchronously so that no message is lost while the module initialises.
self.onmessage = (event) => (app ? deliver(() => app.handle(event.data)) : early.push(event.data));

function deliver(call) {
  try {
    call();
  } catch (error) {
    // A Rust panic aborts the module (a WebAssembly.RuntimeError here); the panic hook has
    // already posted the `panic` event. Anything else is a bug worth seeing.
    if (!(error instanceof WebAssembly.RuntimeError)) throw error;
  }
}

const isHelper = self.name.startsWith('egoexo-helper-');
const asked = Number.parseInt(new URL(self.location.href).searchParams.get('workers') ?? '', 10);
const workers = isHelper
  ? 1
  : Math.min(MAX_WORKERS, Math.max(1, asked > 0 ? asked : (navigator.hardwareConcurrency || 1)));

const helpers = [];
const pool = workers > 1 ? {
  size: workers - 1,
  // Called by the Rust side, once: for a long session's job, or when the first job is done.
  start() {
    const url = new URL('worker.js', import.meta.url);
    for (let i = helpers.length; i < workers - 1; i++) {
      const helper = new Worker(url, { type: 'module', name: `egoexo-helper-${i}` });
      helper.onmessage = (event) => deliver(() => app.handle_helper(i, event.data));
      helper.onerror = (event) => {
        event.preventDefault();
        deliver(() => app.helper_failed(i, event.message || 'the helper worker failed to start'));
      };
      helpers.push(helper);
    }
  },
  post(i, message, transfer) {
    helpers[i].postMessage(message, transfer);
  },
} : undefined;

await init();
// The clock the live connection answers the relay's pings with (Unix ms); the wasm never
// reads one itself.
const clock = () => performance.timeOrigin + performance.now();
app = new WorkerApp(new URL('models/', self.location.href).href, clock, pool);
for (const message of early.splice(0)) deliver(() => app.handle(message));
