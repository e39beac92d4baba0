// A device's socket to the live relay (docs/live-protocol.md), shared by the WebXR page and
// the camera page: the hello on open, the pong to every ping (made in Rust: the relay's time
// is echoed to the nanosecond), reconnection after the closes worth retrying (Rust says which),
// and sending that skips rather than queues behind a slow network.

import { xr_answer, xr_close_may_retry } from './pkg/egoexo_web_worker.js';

export const SUBPROTOCOL = 'egoexo-live.1';
// Frames are skipped, not queued, while the socket holds more than this unsent (about half a
// second of frames): a frame that waits behind a slow network is stale by the time it arrives.
export const MAX_BUFFERED_BYTES = 4 * 1024;
const RETRY_DELAYS_MS = [500, 1000, 2000, 4000, 8000];

const message = (error) => (error instanceof Error ? error.message : String(error));

// `hooks`: `hello()` → the hello (JSON); `nowNs()` → the page's clock (the one its frames are
// stamped with); `onConnecting(retry)`; `onWelcome(welcome)`; `onClosed(reason, code)` for
// every close; `onRetry(delayMs, reason)` before a reconnection; `onFail(text)` when it gives up.
export class DeviceSocket {
  constructor(hooks) {
    this.hooks = hooks;
    this.socket = null;
    this.welcomed = false;
    this.ended = false;
    this.retries = 0;
    this.retryTimer = 0;
    this.sent = 0;
    this.skipped = 0;
  }

  connect() {
    if (this.ended) return;
    const url = new URL('live', location.href);
    url.protocol = location.protocol === 'https:' ? 'wss:' : 'ws:';
    url.hash = '';
    url.search = '';
    this.hooks.onConnecting?.(this.retries > 0);
    let socket;
    try {
      socket = new WebSocket(url.href, SUBPROTOCOL);
    } catch (error) {
      this.hooks.onFail(`Could not open the connection to the relay: ${message(error)}`);
      return;
    }
    socket.binaryType = 'arraybuffer';
    this.socket = socket;
    socket.onopen = () => socket.send(this.hooks.hello());
    socket.onmessage = (event) => this.onMessage(socket, event);
    socket.onclose = (event) => this.onClose(socket, event);
  }

  onMessage(socket, event) {
    if (typeof event.data !== 'string') return; // devices receive no data frames
    let pong;
    try {
      pong = xr_answer(event.data, this.hooks.nowNs());
    } catch (error) {
      console.warn('egoexo: ignoring a relay message:', message(error));
      return;
    }
    if (pong !== undefined) {
      socket.send(pong);
      return;
    }
    const parsed = JSON.parse(event.data);
    if (parsed.type === 'welcome') {
      this.welcomed = true;
      this.retries = 0;
      this.hooks.onWelcome(parsed);
    } else if (parsed.type === 'observer-world') {
      // A watching page's word on this observer's registration (docs/live-protocol.md).
      this.hooks.onObserverWorld?.(parsed);
    } else if (parsed.type === 'wearer-region') {
      // Where a watching page sees the wearer in this camera's image (docs/live-protocol.md).
      this.hooks.onWearerRegion?.(parsed);
    }
  }

  onClose(socket, event) {
    if (socket !== this.socket) return;
    this.socket = null;
    this.welcomed = false;
    const reason = event.reason || (event.code === 1006 ? 'the connection was lost' : 'no reason given');
    this.hooks.onClosed?.(reason, event.code);
    if (this.ended) return;
    if (xr_close_may_retry(event.code)) {
      const delay = RETRY_DELAYS_MS[Math.min(this.retries, RETRY_DELAYS_MS.length - 1)];
      this.retries += 1;
      this.hooks.onRetry?.(delay, reason);
      this.retryTimer = setTimeout(() => this.connect(), delay);
    } else {
      this.hooks.onFail(`The relay closed the connection: ${reason} (${event.code}).`);
    }
  }

  // Whether frames can go out now (welcomed, open).
  get open() {
    return this.welcomed && this.socket?.readyState === WebSocket.OPEN;
  }

  // Sends a text message now (e.g. the calibration on welcome).
  sendText(text) {
    if (this.socket?.readyState === WebSocket.OPEN) this.socket.send(text);
  }

  // Sends a data frame, or skips it behind a slow network; returns whether it went out.
  sendFrame(bytes) {
    if (!this.open) return false;
    if (this.socket.bufferedAmount > MAX_BUFFERED_BYTES) {
      this.skipped += 1;
      return false;
    }
    this.socket.send(bytes);
    this.sent += 1;
    return true;
  }

  close(reason) {
    if (this.ended) return;
    this.ended = true;
    clearTimeout(this.retryTimer);
    if (this.socket && this.socket.readyState <= WebSocket.OPEN) this.socket.close(1000, reason);
    this.socket = null;
  }
}
