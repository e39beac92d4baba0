// What the device pages (xr.html, observe.html) share: the page state on <body data-state>,
// the error panel (#error-panel, #error-message), and the connection lines their relay socket
// (device-socket.js) reports to (#connection, #close-reason).

const $ = (id) => document.getElementById(id);

export function setState(state) {
  document.body.dataset.state = state;
}

export function showError(text) {
  $('error-message').textContent = text;
  $('error-panel').hidden = false;
  setState('error');
}

export function clearError() {
  $('error-panel').hidden = true;
  $('error-message').textContent = '';
}

export function message(error) {
  return error instanceof Error ? error.message : String(error);
}

// The DeviceSocket hooks that show the connection: connecting, welcomed (`state` and
// `doing`, e.g. 'streaming' and 'streaming to'), each close, each reconnection. `onWelcome`
// and `onFail` are the page's own.
export function connectionHooks(label, { state, doing, onWelcome, onFail }) {
  return {
    onConnecting: (retry) => {
      $('connection').textContent = `connecting to ${label}…`;
      setState(retry ? 'reconnecting' : 'connecting');
    },
    onWelcome: (welcome) => {
      onWelcome?.(welcome);
      clearError();
      setState(state);
      $('connection').textContent = `${doing} ${label} (room open until ${welcome.expires_at})`;
    },
    onClosed: (reason, code) => {
      $('close-reason').textContent = `${reason} (${code})`;
    },
    onRetry: (delay, reason) => {
      setState('reconnecting');
      $('connection').textContent = `reconnecting in ${(delay / 1000).toFixed(1)} s (${reason})`;
    },
    onFail,
  };
}

// The room in the address's `#live=…`, if any (`XrJoin` from the wasm module): shown in the
// form (#link-note, #link-label) instead of the code field (#code-field); a damaged link is
// said on the error panel. Returns the join or null.
export function linkJoinFromAddress(XrJoin) {
  let join = null;
  try {
    join = XrJoin.fromFragment(location.hash) ?? null;
  } catch (error) {
    showError(message(error));
  }
  if (join) {
    $('link-label').textContent = join.label;
    $('link-note').hidden = false;
    $('code-field').hidden = true;
  }
  return join;
}

// The device id this page last used (local storage `key`), or null.
export function rememberedDeviceId(key) {
  try {
    return localStorage.getItem(key);
  } catch {
    return null; // storage may be off; the default id is fine
  }
}

export function rememberDeviceId(key, id) {
  try {
    localStorage.setItem(key, id);
  } catch {
    // storage may be off; the default id is fine
  }
}
