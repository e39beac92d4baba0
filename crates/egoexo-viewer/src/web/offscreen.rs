//! Rendering a scene frame into a texture and reading its pixels back: for tests, the bench,
//! and screenshots. Works on WebGPU without a canvas (headless Chromium included) and on WebGL2
//! through a detached scratch canvas.

use crate::camera::OrbitCamera;
use crate::error::{BackendPreference, ViewerError};
use crate::playback::Playback;
use crate::scene::{LayerToggles, SceneGeometry, build_frame, parse_scene, static_lines, view_bounds};

use super::gpu::{self, Gpu};
use super::renderer::Renderer;

/// The format off-screen images are rendered in (and returned as): 8-bit RGBA, display-encoded.
const FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// Renders frame `frame` (rounded and clamped like `seek`) of the scene in `scene_json` at
/// `width × height` pixels with the default view (`view_bounds` at that frame, default layers) and
/// returns its RGBA pixels, rows top to bottom. `Auto` uses WebGPU when a device can be had
/// (no canvas is involved, so presentation does not matter), else WebGL2.
pub(crate) async fn render_offscreen(
    scene_json: &[u8],
    frame: f64,
    width: u32,
    height: u32,
    preference: BackendPreference,
) -> Result<Vec<u8>, ViewerError> {
    let scene = parse_scene(scene_json)?;
    let frame = Playback::new(scene.frames, f64::from(scene.fps)).seek(frame)?;
    if width == 0 || height == 0 || width > 8192 || height > 8192 {
        return Err(ViewerError::BadSize { width, height, max: 8192 });
    }
    // WebGL2 adapters come from a canvas surface; keep both alive while rendering.
    let (gpu, _surface): (Gpu, Option<(web_sys::HtmlCanvasElement, wgpu::Surface<'static>)>) = match preference {
        BackendPreference::WebGpu | BackendPreference::WebGpuUnchecked => (gpu::webgpu().await?, None),
        BackendPreference::WebGl2 => webgl2_offscreen().await?,
        BackendPreference::Auto => match gpu::webgpu().await {
            Ok(gpu) => (gpu, None),
            Err(e) => {
                web_sys::console::info_1(&format!("egoexo viewer: off-screen render on WebGL2 ({e})").into());
                webgl2_offscreen().await?
            }
        },
    };
    let max = gpu::max_texture_side(&gpu).min(8192);
    if width > max || height > max {
        return Err(ViewerError::BadSize { width, height, max });
    }

    let mut renderer = Renderer::new(&gpu.device, &gpu.queue, FORMAT, gpu::msaa_supported(&gpu, FORMAT));
    renderer.set_static_lines(&static_lines(&scene));
    let aspect = width as f32 / height as f32;
    let camera = view_bounds(&scene, frame).map(|b| OrbitCamera::framing(b, aspect)).unwrap_or_default();
    let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some("off-screen frame"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    });
    let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let view = texture.create_view(&Default::default());
    let list = build_frame(&scene, &SceneGeometry::of(&scene), frame, LayerToggles::default());
    renderer.render(&view, (width, height), &camera.view_point(aspect), &list);
    if let Some(error) = scope.pop().await {
        return Err(ViewerError::Gpu(error.to_string()));
    }
    let pixels = gpu::read_texture(&gpu, &texture, width, height).await?;
    if let Some(error) = gpu.health.take_errors().into_iter().next() {
        return Err(ViewerError::Gpu(error));
    }
    Ok(pixels)
}

/// A WebGL2 device through a detached 1×1 canvas, retried a few times when the browser refuses
/// the context (its GPU process may be restarting after a lost device).
async fn webgl2_offscreen() -> Result<(Gpu, Option<(web_sys::HtmlCanvasElement, wgpu::Surface<'static>)>), ViewerError>
{
    let mut last_error = None;
    for delay in [0, 100, 250, 500, 1000] {
        if delay > 0 {
            gpu::sleep_ms(delay).await;
        }
        let canvas = gpu::scratch_canvas(1, 1)?;
        match gpu::webgl2(&canvas).await {
            Ok((gpu, surface)) => return Ok((gpu, Some((canvas, surface)))),
            Err(e) => last_error = Some(e),
        }
    }
    Err(last_error.unwrap_or_else(|| ViewerError::NoWebGl2("no attempt was made".into())))
}
