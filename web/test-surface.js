// The page's test surface: the one object, `window.egoexo`, through which the end-to-end tests
// (tests/e2e/) and the curious read the page. It is read-only and small on purpose, so that
// the page can change inside without the tests changing with it; docs/page-test-surface.md
// documents each field. A change to it bumps `version`.

export const TEST_SURFACE_VERSION = 1;

// Installs `window.egoexo` over the page's state, its Viewer class and the Live panel.
export function installTestSurface(state, Viewer, live) {
  window.egoexo = Object.freeze({
    version: TEST_SURFACE_VERSION,
    // egoexo-viewer's Viewer class (off-screen renders) and the one drawing the page.
    Viewer,
    get viewer() { return state.viewer; },
    // The worker and its WorkerClient (docs/worker-protocol.md).
    get worker() { return state.worker; },
    get client() { return state.client; },
    // The worker's last import summary, reconstruction summary, scene JSON bytes and models.
    get session() { return state.session; },
    get summary() { return state.summary; },
    get scene() { return state.scene; },
    get models() { return state.models; },
    live: Object.freeze({
      get frames() { return live.snapshot().frames; },
      snapshot: () => live.snapshot(),
      resetMeasurements: () => live.resetMeasurements(),
    }),
  });
}
