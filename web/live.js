// The page's Live panel (docs/live-protocol.md): create a room on the server, show its code and
// links, hand the worker the room to watch, and draw what it reconstructs. The socket, the
// take and the reconstruction are the worker's (Rust); this file moves events to the screen
// and measures glass-to-skeleton latency (relay timestamp of the drawn frame → drawn).

import { link_qr_svg, live_fragment } from './pkg/egoexo_viewer.js';

const $ = (id) => document.getElementById(id);
const LATENCY_WINDOW = 300; // frames the latency percentiles are taken over

// Lookaheads the user can pick, with what the eval measured for each (filled from
// live-lookahead.json when the build has it).
const LOOKAHEADS = [0, 4, 8, 16];

export function createLive(state, { fail, showSession, startReconstruction }) {
  const live = {
    room: null, // {room, device_code, device_secret, viewer_secret, expires_at} when this page made it
    joined: false,
    frames: 0, // live frames drawn
    latencies: [], // ms, the last LATENCY_WINDOW
    computeMs: [], // ms the worker took per live frame, the last LATENCY_WINDOW
    arrivals: [], // ms from the frame's time to its arrival in the page (before drawing)
    posted: [], // ms from the frame's time to the worker posting it (relay → worker → reconstructed)
    offsetMs: null, // relay clock − worker clock
    modes: new Set(), // methods seen (ego-exo, ego-only)
    devices: [],
    take: null,
    dropped: 0,
    kept: null,
    closed: null,
    lastFrame: null,
    scene: null, // the drawn frame's SceneData JSON bytes
  };
  state.live = live;

  const relayUrl = () => {
    const api = new URL(state.share.apiBase);
    api.protocol = api.protocol === 'https:' ? 'wss:' : 'ws:';
    api.pathname = '/live';
    return api.href;
  };

  function percentile(values, q) {
    if (values.length === 0) return null;
    const sorted = [...values].sort((a, b) => a - b);
    return sorted[Math.min(sorted.length - 1, Math.round((sorted.length - 1) * q))];
  }

  // Rows of the room's facts: [name, value, copyable (a read-only field to copy from), qr (the
  // caption of a QR code of the value beside it, for a phone to scan)].
  function facts(rows) {
    $('live-facts').replaceChildren(...rows.flatMap(([k, v, copyable, qr]) => {
      const dt = document.createElement('dt');
      const dd = document.createElement('dd');
      dt.textContent = k;
      if (copyable) {
        const input = document.createElement('input');
        input.type = 'text';
        input.readOnly = true;
        input.value = v;
        input.setAttribute('aria-label', k);
        dd.append(input);
        if (qr) {
          const figure = document.createElement('figure');
          figure.className = 'qr';
          const caption = document.createElement('figcaption');
          try {
            figure.innerHTML = link_qr_svg(v); // an SVG the Rust code drew: no outside markup
            caption.textContent = qr;
          } catch (error) {
            caption.textContent = `No QR code: ${error.message}`; // the link above still works
          }
          figure.append(caption);
          dd.append(figure);
        }
      } else {
        dd.textContent = v;
      }
      return [dt, dd];
    }));
  }

  function join(room, secret) {
    live.joined = true;
    live.closed = null;
    $('live-room').hidden = false;
    $('live-start').disabled = true;
    $('live-mode').textContent = 'connecting to the relay…';
    document.body.dataset.state = 'live';
    state.client.live_join(relayUrl(), room, secret, Number($('live-lookahead').value || 4));
  }

  async function start() {
    let response;
    try {
      response = await fetch(`${state.share.apiBase}/api/live/rooms`, { method: 'POST' });
    } catch (error) {
      fail('Could not go live', `${state.share.apiBase}: ${error.message}`);
      return;
    }
    if (!response.ok) {
      let message = `HTTP ${response.status}`;
      try {
        message = (await response.json()).error.message;
      } catch {
        // not JSON
      }
      fail('Could not go live', message);
      return;
    }
    const room = await response.json();
    live.room = room;
    const base = location.origin + location.pathname.replace(/[^/]*$/, '');
    facts([
      ['device code', room.device_code],
      ['headset page', `${base}xr.html#${live_fragment(room.room, room.device_secret)}`, true],
      ['camera page', `${base}observe.html#${live_fragment(room.room, room.device_secret)}`, true,
        'Scan with the phone that will watch the wearer'],
      ['watch link', `${base}#${live_fragment(room.room, room.viewer_secret)}`, true],
      ['replay a session', `egoexo live replay session.egoexo --url ${state.share.apiBase} --room ${room.device_code}`, true],
      ['expires', room.expires_at],
    ]);
    $('live-room').dataset.code = room.device_code;
    join(room.room, room.viewer_secret);
  }

  function stop(keep) {
    if (!live.joined) return;
    live.joined = false;
    $('live-start').disabled = false;
    $('live-keep').disabled = true;
    $('live-stop').disabled = true;
    const name = `live take ${new Date().toISOString().slice(0, 19).replace('T', ' ')}`;
    if (keep) {
      state.busy = false;
      $('live-mode').textContent = 'keeping the take…';
    }
    state.client.live_stop(keep, name);
    if (!keep) {
      $('live-mode').textContent = 'stopped';
      document.body.dataset.state = 'idle';
    }
  }

  // Where a device's world stands: an observer in a world of its own is registered by the
  // worker (`observer_worlds` of the newest frame) before it is fused.
  function worldOf(d) {
    const own = (live.lastFrame?.observer_worlds ?? []).find((o) => o.observer === d.device);
    if (!own) return { state: 'shared', text: d.role === 'wearer' ? 'the wearer\'s' : 'shared', title: '' };
    if (own.state !== 'registered') {
      return { state: own.state, text: `registering — ${Math.floor(own.views_s)} s of views`, title: own.message };
    }
    const sigma = own.sigma_yaw_deg === null ? '' : ` ± ${own.sigma_yaw_deg.toFixed(1)}°`;
    const cm = own.sigma_translation_m === null ? '' : `, ± ${(own.sigma_translation_m * 100).toFixed(0)} cm`;
    const jumps = own.jumps > 0 ? `, after ${own.jumps} jump${own.jumps > 1 ? 's' : ''}` : '';
    return { state: own.state, text: `registered: yaw ${own.yaw_deg.toFixed(1)}°${sigma}${cm}${jumps}`, title: own.message };
  }

  function showDevices(devices) {
    const rows = devices.map((d) => {
      const tr = document.createElement('tr');
      const rate = d.rates_hz.map(([stream, hz]) => `${stream} ${hz.toFixed(0)} Hz`).join(', ') || '–';
      const offset = d.clock_offset_ns === null ? 'measuring…'
        : `${(d.clock_offset_ns / 1e6).toFixed(1)} ± ${(d.clock_uncertainty_ns / 1e6).toFixed(1)} ms`;
      const latency = d.latency_ns === null ? '–' : `${(d.latency_ns / 1e6).toFixed(1)} ms`;
      const world = worldOf(d);
      const cells = [d.device, d.connected ? d.role : `${d.role} (disconnected)`, rate, offset, latency, String(d.frames), world.text];
      tr.replaceChildren(...cells.map((text) => {
        const td = document.createElement('td');
        td.textContent = text;
        return td;
      }));
      tr.lastChild.title = world.title;
      tr.dataset.device = d.device;
      tr.dataset.world = world.state;
      tr.dataset.connected = String(d.connected);
      return tr;
    });
    $('live-devices').tBodies[0].replaceChildren(...rows);
  }

  function showLatency() {
    const p50 = percentile(live.latencies, 0.5);
    const p95 = percentile(live.latencies, 0.95);
    const cost = percentile(live.computeMs, 0.5);
    $('live-latency').textContent = p50 === null ? 'glass-to-skeleton latency: measuring…'
      : `glass-to-skeleton latency: p50 ${p50.toFixed(0)} ms, p95 ${p95.toFixed(0)} ms (last ${live.latencies.length} frames)` +
        (cost === null ? '' : `; the worker takes ${cost.toFixed(0)} ms a frame`);
    $('live-latency').dataset.p50 = String(p50);
    $('live-latency').dataset.p95 = String(p95);
  }

  function onFrame(event) {
    const viewer = state.viewer;
    if (!viewer || !live.joined) return;
    try {
      viewer.set_live_scene_json(event.scene);
    } catch (error) {
      console.warn('live frame not shown:', error.message ?? error);
      return;
    }
    $('plots').hidden = true; // the plots belong to a recorded session's timeline
    const info = event.frame;
    // The drawn frame's scene (SceneData JSON bytes), for the curious and the tests.
    live.scene = event.scene;
    live.frames += 1;
    live.lastFrame = info;
    if (info.compute_ms !== null) {
      live.computeMs.push(info.compute_ms);
      if (live.computeMs.length > LATENCY_WINDOW) live.computeMs.shift();
    }
    live.modes.add(info.method);
    const who = info.exo_observers.length > 0 ? ` (rays from ${info.exo_observers.join(', ')})` : '';
    const networks = info.trained_for_lookahead ? ` · networks trained for lookahead ${info.lookahead}` : '';
    // A room of several wearers: everyone is drawn; the facts are the first wearer's.
    const wearers = info.wearers ?? [];
    const everyone = wearers.length > 1 ? ` · ${wearers.length} wearers drawn (${wearers.join(', ')}; facts of ${wearers[0]})` : '';
    // Observers in worlds of their own are left out until registered.
    const registering = (info.observer_worlds ?? []).filter((o) => o.state !== 'registered');
    const waiting = registering.length === 0 ? ''
      : ` · registering ${registering.map((o) => `${o.observer} (${Math.floor(o.views_s)} s of views)`).join(', ')}: not fused yet`;
    $('live-mode').textContent = (!info.tracked ? 'the wearer is not tracked'
      : info.method === 'ego-only' ? 'ego-only: no observer sees the wearer now (none connected, or no keypoints)'
        : `ego-exo${who}`) + waiting + networks + everyone;
    $('live-mode').dataset.wearers = String(Math.max(1, wearers.length));
    $('live-mode').dataset.method = info.method;
    $('live-mode').dataset.trainedForLookahead = String(info.trained_for_lookahead);
    // Latency: when the frame reached the page, and when it is on screen (the viewer draws in
    // this animation frame).
    if (live.offsetMs !== null) {
      live.arrivals.push(performance.timeOrigin + performance.now() + live.offsetMs - info.timestamp_ms);
      if (live.arrivals.length > LATENCY_WINDOW) live.arrivals.shift();
      if (info.posted_ms !== null && info.posted_ms !== undefined) {
        live.posted.push(info.posted_ms + live.offsetMs - info.timestamp_ms);
        if (live.posted.length > LATENCY_WINDOW) live.posted.shift();
      }
    }
    requestAnimationFrame(() => {
      if (live.offsetMs === null) return;
      const nowRelayMs = performance.timeOrigin + performance.now() + live.offsetMs;
      live.latencies.push(nowRelayMs - info.timestamp_ms);
      if (live.latencies.length > LATENCY_WINDOW) live.latencies.shift();
      showLatency();
    });
  }

  function onStatus(event) {
    live.devices = event.devices;
    live.take = event.take;
    live.dropped = event.dropped;
    if (event.clock_offset_ns !== null) live.offsetMs = event.clock_offset_ns / 1e6;
    showDevices(event.devices);
    const t = event.take;
    $('live-take').textContent = `take: ${t.frames} frames, ${t.head_span_s.toFixed(1)} s; shown ${t.shown} live frames` +
      `${t.skipped ? `, ${t.skipped} passed over` : ''}; dropped by the relay for this page: ${event.dropped}`;
    $('live-take').dataset.dropped = String(event.dropped);
  }

  function onEvent(event) {
    switch (event.type) {
      case 'live-joined':
        $('live-keep').disabled = false;
        $('live-stop').disabled = false;
        $('live-mode').textContent = 'waiting for the wearer…';
        return true;
      case 'live-status':
        onStatus(event);
        return true;
      case 'live-frame':
        onFrame(event);
        return true;
      case 'live-closed':
        live.closed = { code: event.code, reason: event.reason };
        if (live.joined) {
          live.joined = false;
          $('live-start').disabled = false;
          $('live-mode').textContent = `the relay closed the connection: ${event.reason || event.code}`;
        }
        return true;
      case 'live-kept':
        live.kept = event.take;
        $('live-room').hidden = true;
        state.session = event.summary;
        showSession(event.summary);
        startReconstruction();
        return true;
      default:
        return false;
    }
  }

  // The lookahead choices with the eval's figures beside each (ego-exo, 1 observer; from the
  // live networks trained for that lookahead where they ship, else the offline ones), and the
  // default the eval picked: the smallest within 10 % of the offline MPJPE.
  async function fillLookaheads() {
    const select = $('live-lookahead');
    let figures = null;
    try {
      const response = await fetch(new URL('live-lookahead.json', import.meta.url));
      if (response.ok) figures = await response.json();
    } catch {
      // No figures in this build: plain choices.
    }
    select.replaceChildren(...LOOKAHEADS.map((l) => {
      const option = document.createElement('option');
      option.value = String(l);
      const per = Object.entries(figures?.tracking ?? {}).flatMap(([mode, methods]) => {
        const row = methods['ego-exo']?.[String(l)];
        const trained = row?.networks === 'live' ? ', live networks' : '';
        return row ? [`${mode} ${row.mpjpe_cm.toFixed(1)} cm (${row.ratio.toFixed(2)}× offline${trained})`] : [];
      });
      option.textContent = `${l} frames (≥ ${Math.round((l * 1000) / 30)} ms)${per.length ? ` — MPJPE ${per.join(', ')}` : ''}`;
      return option;
    }));
    const chosen = String(figures?.default ?? 4);
    select.value = chosen;
    if (live.joined) state.client.live_lookahead(Number(chosen));
  }

  function wire() {
    const select = $('live-lookahead');
    fillLookaheads();
    select.addEventListener('change', () => state.client.live_lookahead(Number(select.value)));
    $('live-start').addEventListener('click', start);
    $('live-keep').addEventListener('click', () => stop(true));
    $('live-stop').addEventListener('click', () => stop(false));
  }

  // A copy of what the Live panel has seen, for the test surface (test-surface.js).
  function snapshot() {
    return {
      frames: live.frames,
      modes: [...live.modes],
      devices: live.devices,
      take: live.take,
      kept: live.kept,
      dropped: live.dropped,
      closed: live.closed,
      latencies: [...live.latencies],
      computeMs: [...live.computeMs],
      arrivals: [...live.arrivals],
      posted: [...live.posted],
      lastFrame: live.lastFrame,
      scene: live.scene,
    };
  }

  // Forgets the latency measurements (the live bench measures each lookahead afresh).
  function resetMeasurements() {
    for (const list of [live.latencies, live.computeMs, live.arrivals, live.posted]) list.length = 0;
  }

  return { wire, join, onEvent, snapshot, resetMeasurements };
}
