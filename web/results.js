// The session and result panels: what was imported (participants, devices, observers and
// their worlds, warnings), what was reconstructed (method, evidence, accuracy, people), and
// handing a reconstruction to the viewer. Also asks the worker to reconstruct and to switch
// the participant shown.

import { participant_colour } from './pkg/egoexo_viewer.js';
import { $, fail, markOnce, pauseShown, setBusy, setState, showProgress, state } from './page.js';
import { applyToggles, drawPlots, showCameraChoices } from './view.js';

// Reconstructs the open session offline (ego-exo and the ego-only overlay).
export function startReconstruction() {
  pauseShown();
  setBusy(true);
  setState('busy');
  showProgress('reconstructing…', 0);
  state.reconstructStarted = performance.now();
  state.client.reconstruct(true);
}

// The user's `prefers-reduced-motion: reduce` (an accessibility setting of the system or
// browser; the end-to-end tests ask for it too, so the software renderer does not draw a
// playing view while a test reads something else).
function prefersReducedMotion() {
  return window.matchMedia?.('(prefers-reduced-motion: reduce)').matches ?? false;
}

function facts(dl, rows) {
  dl.replaceChildren(...rows.flatMap(([k, v]) => {
    const dt = document.createElement('dt');
    const dd = document.createElement('dd');
    dt.textContent = k;
    dd.textContent = v;
    return [dt, dd];
  }));
}

// A capture of several participants: one button per participant reconstructed, in its
// colour; the pressed one is shown (their facts, plots and exports).
function showParticipants(s) {
  const box = $('participants');
  const people = (s.participants ?? []).filter((p) => p.reconstruct);
  box.hidden = people.length === 0;
  box.replaceChildren(...people.map((p) => {
    const button = document.createElement('button');
    button.type = 'button';
    button.dataset.participant = p.id;
    button.setAttribute('aria-pressed', String(p.id === s.participant));
    const swatch = document.createElement('span');
    swatch.className = 'swatch';
    swatch.style.background = participant_colour(p.colour);
    button.append(swatch, p.id);
    button.title = `${p.devices.join(', ')}${p.camera ? `; camera ${p.camera}` : ''}`;
    button.addEventListener('click', () => selectParticipant(p.id));
    return button;
  }));
}

function selectParticipant(id) {
  if (state.busy || state.session?.participant === id) return;
  // The moment shown, on the session clock: the other participant's timeline may start
  // elsewhere.
  const v = state.viewer;
  const moment = v && state.summary ? v.start_s() + v.time() : null;
  const how = state.openedShare ? state.sharedBy : '';
  state.selecting = { id, moment, how };
  setBusy(true);
  setState('busy');
  state.client.select_participant(id);
}

export function showSession(s) {
  $('session-panel').hidden = false;
  $('session-name').textContent = s.name;
  showParticipants(s);
  facts($('session-facts'), [
    ['source', s.source],
    ['timeline', `${s.frames} frames at ${s.fps} fps (${s.duration_s.toFixed(1)} s)`],
    ['wearer', `${s.tracking_points}-point tracking: ${s.devices.join(', ')}`
      + (s.tracking_reason ? ` (${s.tracking_reason})` : '')],
    ...(s.wrists ?? []).map((w) => [`${w.side} wrist`,
      `tracked on ${w.tracked_percent.toFixed(1)}% of frames, longest gap ${w.longest_gap_s.toFixed(2)} s (${w.source})`]),
    ['floor', s.floor ? `${s.floor.height_m.toFixed(3)} m, from ${s.floor.source}` : 'unknown'],
    ...(s.observers.length === 0 ? [['observers', 'none']] : s.observers.map((o) =>
      [o.id, `${o.camera}, ` + (o.needs_detection
        ? `video ${o.video}: keypoints found by the detector when reconstructing`
        : `keypoints in ${o.keypoint_frames} frames`)
        + (o.world ? `; world: ${o.world}` : '') + (o.fused === false ? ' — not fused' : '')])),
    ['ground truth', s.ground_truth ? 'yes' : 'no'],
  ]);
  $('session-warnings').replaceChildren(...[...(state.notRead ?? []), ...s.warnings].map((w) => {
    const li = document.createElement('li');
    li.textContent = w;
    return li;
  }));
  $('result-facts').replaceChildren();
}

export function showScene(scene, summary, how, keepMoment = null) {
  const viewer = state.viewer;
  try {
    if (!viewer) throw new Error('the 3D view could not start (see above)');
    viewer.set_scene_json(scene);
    state.scene = scene;
    state.summary = summary;
    // The viewer draws in its next animation frame: the frame after that has the skeleton on
    // screen. Time to first skeleton = this mark's startTime (from navigation start).
    requestAnimationFrame(() => requestAnimationFrame(() => markOnce('egoexo:first-skeleton')));
  } catch (error) {
    fail('Cannot show the reconstruction', error.message ?? String(error));
    return;
  }
  const rows = [
    ['method', `${summary.method}, ${summary.tracking_points}-point`],
    ['reconstructed', `${summary.valid_frames} of ${summary.frames} frames ${how}`],
    ['exo evidence', `${summary.exo_evidence_frames} frames`],
  ];
  for (const d of summary.detection ?? []) {
    const rate = d.ms > 0 ? `, ${(d.detected / (d.ms / 1000)).toFixed(1)} detections/s` : '';
    rows.push([`detector (${d.observer})`, `the wearer in ${d.detected} of ${d.frames} video frames${rate}`]);
  }
  if (summary.accuracy) {
    const a = summary.accuracy;
    rows.push(['MPJPE vs ground truth', `${a.ego_exo_mpjpe_cm.toFixed(1)} cm` +
      (a.ego_only_mpjpe_cm == null ? '' : ` (ego-only ${a.ego_only_mpjpe_cm.toFixed(1)} cm)`)]);
  }
  // A capture: every participant's row, and who was who in cameras without identities.
  for (const p of summary.participants ?? []) {
    if (p.id === summary.participant) continue;
    rows.push([p.id, `${p.method}, ${p.valid_frames} of ${p.frames} frames` +
      (p.accuracy ? `, MPJPE ${p.accuracy.ego_exo_mpjpe_cm.toFixed(1)} cm` : '')]);
  }
  for (const a of summary.association ?? []) {
    const assigned = Object.entries(a.assigned).map(([id, n]) => `${n} to ${id}`).join(', ') || 'none assigned';
    rows.push([`people (${a.observer})`, `${a.detections} over ${a.frames} frames: ${assigned}; ${a.unassigned} bystanders`]);
  }
  facts($('result-facts'), rows);
  $('view-panel').hidden = false;
  const frames = viewer.frames();
  $('scrubber').max = String(Math.max(0, frames - 1));
  $('frame-count').textContent = `${frames} frames`;
  $('frame-count').hidden = false;
  applyToggles();
  showCameraChoices(viewer);
  drawPlots();
  $('rerun-button').hidden = !(state.openedShare?.includes_recording);
  // A share without its recording has no session to save.
  $('save-session').hidden = Boolean(state.openedShare && !state.openedShare.includes_recording);
  viewer.clear_loop();
  const time = state.pendingTime;
  state.pendingTime = null;
  if (keepMoment != null) {
    // Another participant of the same capture: the same moment on the session clock.
    viewer.seek(Math.max(0, Math.min(frames - 1, Math.round((keepMoment - viewer.start_s()) * viewer.fps()))));
  } else if (time) {
    // A link to a moment: show that frame (paused), or play its range in a loop.
    const fps = viewer.fps();
    const start = Math.min(frames - 1, Math.round(time.start * fps));
    viewer.seek(start);
    if (time.end != null) {
      viewer.set_loop(start, Math.min(frames - 1, Math.round(time.end * fps)));
      viewer.play();
    } else {
      viewer.pause();
    }
  } else {
    viewer.seek(0);
    // Plays at once, unless the user asked their system for less motion: then the first
    // frame waits for Play. (A link's range above still loops: the link asked for it.)
    if (prefersReducedMotion()) viewer.pause();
    else viewer.play();
  }
  setBusy(false);
  setState('ready');
}
