// The module Web Worker: session import, reconstruction and export, all in Rust
// (pkg/egoexo_web_worker.js). This file only moves bytes and messages.
//
// Page → worker: {type: 'warm-up'} (load the models now)
//                {type: 'open', input: {kind: 'archive', name, bytes} | {kind: 'files', name, paths, contents}}
//                {type: 'reconstruct', overlay}   {type: 'export', format}   {type: 'panic-for-test'}
// Worker → page: {type: 'status', text}  {type: 'models', summary}  {type: 'progress', stage, done, total}
//                {type: 'imported', summary}  {type: 'reconstructed', scene, summary, elapsedMs}
//                {type: 'exported', bytes, fileName, mimeType}  {type: 'error', stage, message}
//                {type: 'panic', message}

import init, { WorkerApp, install_panic_reporter, panic_for_test } from './pkg/egoexo_web_worker.js';

const MODELS_URL = new URL('models/', self.location.href);
const CACHE_NAME = 'egoexo-models';

let app = null;
let ready = null;
let panicked = false;

const post = (message, transfer = []) => self.postMessage(message, transfer);

// Assigned synchronously so that no early message is lost while the module initialises.
self.onmessage = async (event) => {
  const message = event.data;
  let stage = 'models';
  try {
    await whenReady();
    switch (message.type) {
      case 'warm-up':
        break;
      case 'open': {
        stage = 'import';
        post({ type: 'progress', stage: 'import', done: 0, total: 1 });
        const input = message.input;
        const summary = input.kind === 'archive'
          ? app.import_archive(input.name, input.bytes)
          : app.import_files(input.name, input.paths, input.contents);
        post({ type: 'imported', summary });
        break;
      }
      case 'reconstruct': {
        stage = 'reconstruct';
        const started = performance.now();
        const scene = app.reconstruct((part, done, total) => {
          post({ type: 'progress', stage: part, done, total });
          return true;
        }, message.overlay !== false);
        const elapsedMs = performance.now() - started;
        post({ type: 'reconstructed', scene, summary: app.reconstruction_summary(), elapsedMs }, [scene.buffer]);
        break;
      }
      case 'export': {
        stage = 'export';
        const file = app.export(message.format);
        const bytes = file.bytes;
        post({ type: 'exported', bytes, fileName: file.file_name, mimeType: file.mime_type }, [bytes.buffer]);
        file.free();
        break;
      }
      case 'panic-for-test':
        panic_for_test('a panic requested by the test suite');
        break;
      default:
        throw new Error(`unknown message type ${message.type}`);
    }
  } catch (error) {
    // After a panic the module is dead (wasm aborts); the reporter has posted the message.
    if (!panicked) post({ type: 'error', stage, message: error?.message ?? String(error) });
  }
};

function whenReady() {
  if (!ready) {
    ready = start().catch((error) => {
      ready = null; // try again on the next message
      throw error;
    });
  }
  return ready;
}

async function start() {
  await init();
  install_panic_reporter((message) => {
    panicked = true;
    post({ type: 'panic', message });
  });
  app = new WorkerApp();
  post({ type: 'status', text: 'loading the models…' });
  const summary = await loadModels();
  post({ type: 'models', summary });
}

// Fetches models/manifest.json and the files it lists, from the Cache API when cached (keyed
// by sha256), and loads them; Rust checks every file's sha256 against the manifest.
async function loadModels() {
  const manifest = await fetchBytes(new URL('manifest.json', MODELS_URL), { cache: 'no-cache' });
  const listed = WorkerApp.model_files(manifest);
  const cache = await openCache();
  const keyOf = (f) => `${new URL(f.file, MODELS_URL).href}?sha256=${f.sha256}`;
  const load = async (useCache) => {
    const files = new Map();
    const fetched = [];
    await Promise.all(listed.map(async (f) => {
      const hit = useCache && cache ? await cache.match(keyOf(f)) : undefined;
      if (hit) {
        files.set(f.file, new Uint8Array(await hit.arrayBuffer()));
      } else {
        files.set(f.file, await fetchBytes(new URL(f.file, MODELS_URL)));
        fetched.push(f);
      }
    }));
    const summary = app.load_models(manifest, files);
    if (cache) {
      // Cache only what checked out, and forget other versions.
      await Promise.all(fetched.map((f) => cache.put(keyOf(f), new Response(files.get(f.file)))));
      const wanted = new Set(listed.map(keyOf));
      for (const request of await cache.keys()) {
        if (!wanted.has(request.url)) await cache.delete(request);
      }
    }
    return summary;
  };
  try {
    return await load(true);
  } catch (error) {
    if (!cache) throw error;
    // A cached file may be stale or damaged: fetch everything again once.
    await Promise.all(listed.map((f) => cache.delete(keyOf(f))));
    return await load(false);
  }
}

async function openCache() {
  try {
    return self.caches ? await self.caches.open(CACHE_NAME) : null;
  } catch {
    return null; // e.g. an insecure context or storage disabled: fetch every time
  }
}

async function fetchBytes(url, options) {
  const response = await fetch(url, options);
  if (!response.ok) {
    const path = url.pathname.split('/').slice(-2).join('/');
    throw new Error(`cannot fetch ${path}: HTTP ${response.status} ${response.statusText}`);
  }
  return new Uint8Array(await response.arrayBuffer());
}
