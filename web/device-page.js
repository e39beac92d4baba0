// What the device pages (xr.html, observe.html) share: the page state on <body data-state>,
// the error panel (#error-panel, #error-message), the connection lines their relay socket
// (device-socket.js) reports to (#connection, #close-reason), and the join form (JoinForm).

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

// The join form of a device page (#join-form in the page's HTML: a heading and the page's own
// fields). This builds what every device page asks for around them: after the heading, the
// room (from the address's `#live=…` link, or a device code) and this device's id, remembered
// in local storage under `idKey`; at the end, the Enter button (`enterLabel`), Stop and a note
// (#enter-button, #stop-button, #support-note). `XrJoin` is the wasm module's; `page` is the
// page's state, whose `run` is what is streaming (with a `stop()`) or null: `start` runs on
// submit while nothing runs, Stop stops the run.
export class JoinForm {
  constructor(XrJoin, { idKey, defaultId, codeHelp, enterLabel, start, page }) {
    this.XrJoin = XrJoin;
    this.idKey = idKey;
    const form = $('join-form');
    const fields = document.createElement('template');
    fields.innerHTML = `
      <p id="link-note" hidden>Joining <strong id="link-label"></strong> from this link.</p>
      <div id="code-field">
        <label for="code-input">Device code</label>
        <input id="code-input" name="code" type="text" autocomplete="off" autocapitalize="characters"
          spellcheck="false" placeholder="7KQ-M4T" aria-describedby="code-help">
        <p id="code-help" class="note"></p>
      </div>
      <label for="device-input">Device id</label>
      <input id="device-input" name="device" type="text" autocomplete="off" spellcheck="false" maxlength="64">`;
    form.querySelector('h2').after(fields.content);
    const end = document.createElement('template');
    end.innerHTML = `
      <div class="buttons">
        <button id="enter-button" type="submit" disabled></button>
        <button id="stop-button" type="button" hidden>Stop</button>
      </div>
      <p id="support-note" class="note" hidden></p>`;
    form.append(end.content);
    $('code-help').textContent = codeHelp;
    $('enter-button').textContent = enterLabel;
    this.ui = {
      form,
      code: $('code-input'),
      device: $('device-input'),
      enter: $('enter-button'),
      stop: $('stop-button'),
      supportNote: $('support-note'),
    };
    this.ui.device.value = rememberedDeviceId(idKey) ?? defaultId;
    this.linkJoin = this.#linkJoinFromAddress();
    form.addEventListener('submit', (event) => {
      event.preventDefault();
      if (!page.run) start();
    });
    this.ui.stop.addEventListener('click', () => page.run?.stop());
  }

  // The room in the address's `#live=…`, if any: shown in the form (#link-note) instead of the
  // code field; a damaged link is said on the error panel.
  #linkJoinFromAddress() {
    let join = null;
    try {
      join = this.XrJoin.fromFragment(location.hash) ?? null;
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

  // The room to join and this device's id, checked by `checkHello(join, deviceId)` (the wasm
  // hello, which throws on a bad id); the id is remembered and the Enter button disabled.
  // Null, with the error shown, when either is refused.
  take(checkHello) {
    clearError();
    let join;
    try {
      join = this.linkJoin ?? this.XrJoin.parse(this.ui.code.value);
      checkHello(join, this.ui.device.value);
    } catch (error) {
      showError(message(error));
      return null;
    }
    const deviceId = this.ui.device.value.trim();
    rememberDeviceId(this.idKey, deviceId);
    this.ui.enter.disabled = true;
    return { join, deviceId };
  }

  // A stream started (`true`: Stop shown) or ended (Enter enabled again, Stop hidden).
  running(yes) {
    this.ui.stop.hidden = !yes;
    this.ui.enter.disabled = yes;
  }

  // A note under the buttons (why the page cannot stream, or how it will).
  note(text) {
    this.ui.supportNote.textContent = text;
    this.ui.supportNote.hidden = false;
  }

  // The page cannot stream here: `text` says why.
  unsupported(text) {
    this.note(text);
    if (document.body.dataset.state !== 'error') setState('unsupported');
  }

  // The page is ready to join.
  ready() {
    this.ui.enter.disabled = false;
    if (document.body.dataset.state !== 'error') setState('ready');
  }
}

// The device id this page last used (local storage `key`), or null.
function rememberedDeviceId(key) {
  try {
    return localStorage.getItem(key);
  } catch {
    return null; // storage may be off; the default id is fine
  }
}

function rememberDeviceId(key, id) {
  try {
    localStorage.setItem(key, id);
  } catch {
    // storage may be off; the default id is fine
  }
}
