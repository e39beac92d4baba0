// The module Web Worker. Everything it does — reading the page's requests, fetching and
// caching the models, importing, reconstructing, exporting, answering with events — is Rust
// (`WorkerApp` in pkg/egoexo_web_worker.js; the protocol is docs/worker-protocol.md). This
// file only hands the messages over.

import init, { WorkerApp } from './pkg/egoexo_web_worker.js';

const early = [];
let app = null;

// Assigned synchronously so that no message is lost while the module initialises.
self.onmessage = (event) => (app ? deliver(event.data) : early.push(event.data));

function deliver(message) {
  try {
    app.handle(message);
  } catch (error) {
    // A Rust panic aborts the module (a WebAssembly.RuntimeError here); the panic hook has
    // already posted the `panic` event. Anything else is a bug worth seeing.
    if (!(error instanceof WebAssembly.RuntimeError)) throw error;
  }
}

await init();
// The clock the live connection answers the relay's pings with (Unix ms); the wasm never
// reads one itself.
app = new WorkerApp(new URL('models/', self.location.href).href, () => performance.timeOrigin + performance.now());
for (const message of early.splice(0)) deliver(message);
