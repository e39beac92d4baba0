// The 3D view and its timeline: starting the viewer on the canvas, the layer toggles, the
// camera choices and keys, the plots under the scrubber and the frame readout. What is drawn
// is the viewer's (Rust, egoexo-viewer); this module places it and wires the controls.

import { Viewer, fragment_with_time } from './pkg/egoexo_viewer.js';
import { $, params, showError, state } from './page.js';

export async function startViewer() {
  const canvas = $('view');
  const preference = params.get('backend') ?? 'auto';
  try {
    state.viewer = await Viewer.create(canvas, preference);
  } catch (error) {
    $('backend').textContent = 'renderer: unavailable';
    showError('The 3D view could not start', error.message ?? String(error));
    return;
  }
  $('backend').textContent = `renderer: ${state.viewer.backend()}`;
  state.viewer.on_frame(onFrame);
  const resize = () => {
    const box = $('canvas-box').getBoundingClientRect();
    state.viewer.resize(box.width, box.height, window.devicePixelRatio || 1);
  };
  new ResizeObserver(resize).observe($('canvas-box'));
  resize();
}

export function applyToggles() {
  const v = state.viewer;
  if (!v) return;
  v.set_show_body($('show-body').checked);
  v.set_show_ego_only($('show-ego-only').checked);
  v.set_show_ground_truth($('show-ground-truth').checked);
  v.set_show_rays($('show-rays').checked);
}

// The camera controls for the scene just shown: follow as the viewer decided (on for a wearer
// who walks about, until the user chooses), and one view per observer.
export function showCameraChoices(viewer) {
  $('follow').checked = viewer.follows();
  const select = $('view-from');
  const orbit = select.options[0];
  select.replaceChildren(orbit, ...viewer.observer_ids().map((id, i) => {
    const option = document.createElement('option');
    option.value = String(i);
    option.textContent = `observer ${id}`;
    return option;
  }));
  select.value = String(viewer.view_from_observer());
}

function setViewFrom(index) {
  const v = state.viewer;
  if (!v) return;
  v.set_view_from_observer(index);
  $('view-from').value = String(v.view_from_observer());
}

// View shortcuts (the viewer itself handles playback keys): B bodies, F follow, O next view,
// R re-frame, ? help. Ignored while typing in a field.
function onViewKey(e) {
  if (e.ctrlKey || e.metaKey || e.altKey || e.defaultPrevented) return;
  const t = e.target;
  const typing = t && (t.isContentEditable || ['TEXTAREA', 'SELECT'].includes(t.tagName)
    || (t.tagName === 'INPUT' && !['checkbox', 'radio', 'range', 'button'].includes(t.type)));
  if (typing) return;
  if (e.key === '?') {
    $('help-dialog').showModal();
    e.preventDefault();
    return;
  }
  const v = state.viewer;
  if (!v || v.frames() === 0) return;
  switch (e.key.toLowerCase()) {
    case 'b':
      $('show-body').checked = !$('show-body').checked;
      applyToggles();
      break;
    case 'f':
      $('follow').checked = !$('follow').checked;
      v.set_follow($('follow').checked);
      break;
    case 'o': {
      const views = v.observer_ids().length + 1;
      setViewFrom(((v.view_from_observer() + 2) % views) - 1);
      break;
    }
    case 'r':
      v.reset_camera();
      break;
    default:
      return;
  }
  e.preventDefault();
}

// The plots share the scrubber's time axis: the canvas spans the scrubber's track (its width
// less the thumb), so a frame sits at the same x in both. The viewer draws the image and
// says what lies where; the page only places it.
const SCRUBBER_THUMB_PX = 8;

function plotAxis() {
  const track = $('scrubber').getBoundingClientRect();
  const box = $('plots').getBoundingClientRect();
  return { left: track.left - box.left + SCRUBBER_THUMB_PX, width: Math.max(1, track.width - 2 * SCRUBBER_THUMB_PX) };
}

export function drawPlots() {
  const v = state.viewer;
  const plots = $('plots');
  const layout = v && v.frames() > 1 ? v.plot_layout() : null;
  if (!layout || layout.rows.length === 0) {
    plots.hidden = true;
    state.plotAxis = null;
    return;
  }
  plots.hidden = false;
  const axis = plotAxis();
  const width = Math.round(axis.width);
  const canvas = $('plot-canvas');
  canvas.width = width;
  canvas.height = layout.height;
  canvas.style.width = `${width}px`;
  canvas.style.height = `${layout.height}px`;
  canvas.style.left = `${axis.left}px`;
  canvas.getContext('2d').putImageData(new ImageData(v.plot_image(width), width, layout.height), 0, 0);
  $('plot-labels').style.width = `${axis.left}px`;
  $('plot-labels').replaceChildren(...layout.rows.map((row) => {
    const label = document.createElement('span');
    label.textContent = row.kind === 'error' ? `${row.label} 0–${layout.error_max_cm}` : row.label;
    label.style.top = `${row.top + row.height / 2}px`;
    return label;
  }));
  state.plotAxis = { left: axis.left, width };
  movePlayhead(v.frame());
}

function movePlayhead(frame) {
  const axis = state.plotAxis;
  if (!axis || !state.viewer) return;
  $('plot-playhead').style.left = `${axis.left + state.viewer.plot_x_of_frame(frame, axis.width)}px`;
}

function wirePlots() {
  const canvas = $('plot-canvas');
  const frameAt = (e) => state.viewer.plot_frame_at(e.offsetX, canvas.clientWidth);
  canvas.addEventListener('click', (e) => state.viewer?.seek(frameAt(e)));
  canvas.addEventListener('mousemove', (e) => {
    if (!state.viewer) return;
    const hover = $('plot-hover');
    hover.textContent = state.viewer.plot_text(frameAt(e));
    hover.hidden = false;
    hover.style.left = `${Math.min(canvas.offsetLeft + e.offsetX + 12, $('plots').clientWidth - hover.offsetWidth - 4)}px`;
  });
  canvas.addEventListener('mouseleave', () => { $('plot-hover').hidden = true; });
  new ResizeObserver(() => drawPlots()).observe($('timeline'));
}

function onFrame(frame, timeSeconds) {
  movePlayhead(frame);
  const frames = state.viewer.frames();
  const playing = state.viewer.is_playing();
  $('frame-readout').textContent = `frame ${frame + 1} / ${frames} · ${timeSeconds.toFixed(2)} s`;
  if (document.activeElement !== $('scrubber')) $('scrubber').value = String(frame);
  $('play-button').textContent = playing ? 'Pause' : 'Play';
  // While the user scrubs or steps, the address follows: copying it shares the moment.
  if (state.linkable && !playing && frames > 0 && document.body.dataset.state === 'ready') {
    const url = new URL(location.href);
    url.hash = fragment_with_time(location.hash, timeSeconds);
    history.replaceState(null, '', url);
  }
}

// Wires the view's own controls (the viewer handles playback keys itself).
export function wireViewControls() {
  for (const id of ['show-body', 'show-ego-only', 'show-ground-truth', 'show-rays']) {
    $(id).addEventListener('change', applyToggles);
  }
  $('follow').addEventListener('change', (e) => state.viewer?.set_follow(e.target.checked));
  $('view-from').addEventListener('change', (e) => setViewFrom(Number(e.target.value)));
  $('help-button').addEventListener('click', () => $('help-dialog').showModal());
  $('help-close').addEventListener('click', () => $('help-dialog').close());
  window.addEventListener('keydown', onViewKey);
  $('play-button').addEventListener('click', () => state.viewer?.toggle_play());
  $('step-back').addEventListener('click', () => state.viewer?.step(-1));
  $('step-forward').addEventListener('click', () => state.viewer?.step(1));
  $('scrubber').addEventListener('input', (e) => state.viewer?.seek(Number(e.target.value)));
  $('speed').addEventListener('change', (e) => state.viewer?.set_speed(Number(e.target.value)));
  wirePlots();
}
