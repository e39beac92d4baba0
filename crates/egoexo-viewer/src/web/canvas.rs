//! The canvas and what draws on it: the backend chosen for a preference (WebGPU after a
//! presentation probe, else WebGL2), a WebGL2 target retried on a fresh canvas element (what
//! the recovery from a lost WebGPU device uses), and the renderer drawing one frame.

use web_sys::HtmlCanvasElement;

use super::gpu::{self, Gpu};
use super::log_warn;
use super::renderer::Renderer;
use crate::camera::ViewPoint;
use crate::error::{BackendPreference, ViewerError};
use crate::scene::FrameDrawList;

/// The canvas, its device and surface, and the renderer drawing into it.
pub(super) struct CanvasTarget {
    pub(super) canvas: HtmlCanvasElement,
    pub(super) gpu: Gpu,
    surface: wgpu::Surface<'static>,
    pub(super) config: wgpu::SurfaceConfiguration,
    pub(super) renderer: Renderer,
}

impl CanvasTarget {
    fn new(canvas: HtmlCanvasElement, gpu: Gpu, surface: wgpu::Surface<'static>) -> Result<Self, ViewerError> {
        let (width, height) = (canvas.width().max(1), canvas.height().max(1));
        let config = gpu::configure_surface(&gpu, &surface, width, height)?;
        let renderer = Renderer::new(&gpu.device, &gpu.queue, config.format, gpu::msaa_supported(&gpu, config.format));
        Ok(Self { canvas, gpu, surface, config, renderer })
    }

    /// Sets the drawing buffer to `width × height` pixels (clamped to the device's limit).
    pub(super) fn resize(&mut self, width: u32, height: u32) {
        let max = gpu::max_texture_side(&self.gpu);
        let (width, height) = (width.clamp(1, max), height.clamp(1, max));
        if (width, height) == (self.config.width, self.config.height) {
            return;
        }
        self.canvas.set_width(width);
        self.canvas.set_height(height);
        self.config.width = width;
        self.config.height = height;
        self.surface.configure(&self.gpu.device, &self.config);
    }

    /// Draws `list` seen by `camera` and presents it. `false` when the canvas gave no texture
    /// this time (draw again on the next animation frame).
    pub(super) fn draw(&mut self, view_point: &ViewPoint, list: &FrameDrawList) -> Result<bool, ViewerError> {
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(frame) | wgpu::CurrentSurfaceTexture::Suboptimal(frame) => frame,
            wgpu::CurrentSurfaceTexture::Outdated | wgpu::CurrentSurfaceTexture::Lost => {
                self.surface.configure(&self.gpu.device, &self.config);
                return Ok(false);
            }
            wgpu::CurrentSurfaceTexture::Timeout | wgpu::CurrentSurfaceTexture::Occluded => return Ok(false),
            wgpu::CurrentSurfaceTexture::Validation => {
                return Err(ViewerError::Gpu("the canvas surface raised a validation error".into()));
            }
        };
        let view = frame.texture.create_view(&Default::default());
        self.renderer.render(&view, (self.config.width, self.config.height), view_point, list);
        self.gpu.queue.present(frame);
        Ok(true)
    }
}

/// A fresh canvas in place of `old` (same attributes: id, classes, style, size), for when `old`
/// already holds a context of the other kind (a canvas keeps its first context type for life).
pub(super) fn replace_canvas(old: &HtmlCanvasElement) -> Result<HtmlCanvasElement, ViewerError> {
    let fresh = gpu::scratch_canvas(old.width(), old.height())?;
    for name in old.get_attribute_names().iter() {
        if let Some(name) = name.as_string()
            && name != "style"
            && let Some(value) = old.get_attribute(&name)
        {
            fresh.set_attribute(&name, &value).map_err(|e| ViewerError::Dom(format!("copying {name}: {e:?}")))?;
        }
    }
    // Inline styles through the CSSOM: a Content-Security-Policy without 'unsafe-inline'
    // refuses a `style` attribute set by script.
    fresh.style().set_css_text(&old.style().css_text());
    if old.parent_node().is_some() {
        old.replace_with_with_node_1(&fresh).map_err(|e| ViewerError::Dom(format!("replacing the canvas: {e:?}")))?;
    }
    Ok(fresh)
}

/// Pauses between WebGL2 attempts, ms: right after a WebGPU device is lost the browser's GPU
/// process may still be restarting and refuse new contexts for a moment.
const WEBGL2_RETRY_DELAYS_MS: [i32; 4] = [100, 250, 500, 1000];

/// A WebGL2 target on `canvas` (unless `fresh_canvas`), else on a fresh canvas put in its
/// place (a canvas that holds another kind of context cannot give a WebGL2 one), retried a few
/// times when the browser refuses the context.
pub(super) async fn webgl2_target(canvas: HtmlCanvasElement, fresh_canvas: bool) -> Result<CanvasTarget, ViewerError> {
    let canvas = if fresh_canvas {
        replace_canvas(&canvas)?
    } else {
        match gpu::webgl2(&canvas).await {
            Ok((gpu, surface)) => return CanvasTarget::new(canvas, gpu, surface),
            Err(e) => {
                log_warn(&format!("{e}; retrying on a fresh canvas element"));
                replace_canvas(&canvas)?
            }
        }
    };
    let mut attempt = gpu::webgl2(&canvas).await;
    for delay in WEBGL2_RETRY_DELAYS_MS {
        match attempt {
            Ok(_) => break,
            Err(e) => log_warn(&format!("{e}; retrying in {delay} ms")),
        }
        gpu::sleep_ms(delay).await;
        attempt = gpu::webgl2(&canvas).await;
    }
    let (gpu, surface) = attempt?;
    CanvasTarget::new(canvas, gpu, surface)
}

/// A WebGPU target on `canvas`, after checking that WebGPU can present at all when `check`.
async fn webgpu_target(canvas: HtmlCanvasElement, check: bool) -> Result<CanvasTarget, ViewerError> {
    let gpu = gpu::webgpu().await?;
    if check {
        gpu::probe_webgpu_presentation(&gpu).await.map_err(ViewerError::WebGpuCannotPresent)?;
    }
    let surface = match gpu::webgpu_surface(&gpu, &canvas) {
        Ok(surface) => (canvas, surface),
        Err(_) => {
            let fresh = replace_canvas(&canvas)?;
            let surface = gpu::webgpu_surface(&gpu, &fresh)?;
            (fresh, surface)
        }
    };
    CanvasTarget::new(surface.0, gpu, surface.1)
}

/// The target for `preference`: forced backends or an error; `Auto` tries WebGPU (verified)
/// and falls back to WebGL2, logging why.
pub(super) async fn connect(
    canvas: HtmlCanvasElement,
    preference: BackendPreference,
) -> Result<CanvasTarget, ViewerError> {
    match preference {
        BackendPreference::WebGpu => webgpu_target(canvas, true).await,
        BackendPreference::WebGpuUnchecked => webgpu_target(canvas, false).await,
        BackendPreference::WebGl2 => webgl2_target(canvas, false).await,
        BackendPreference::Auto => match webgpu_target(canvas.clone(), true).await {
            Ok(target) => Ok(target),
            Err(e) => {
                web_sys::console::info_1(&format!("egoexo viewer: using WebGL2 ({e})").into());
                webgl2_target(canvas, false).await
            }
        },
    }
}
