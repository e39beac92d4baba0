//! Getting a working GPU device in the browser: WebGPU (checked for real: it must be able to
//! present to a canvas) or WebGL2, device health (lost / uncaptured errors, which would
//! otherwise panic inside wgpu), surfaces, and texture read-back.
//!
//! Headless Chromium with `--enable-unsafe-webgpu` hands out a WebGPU adapter and device that
//! render off-screen correctly, but presenting to a canvas fails asynchronously (the device is
//! lost while every wgpu call still returns normally). [`probe_webgpu_presentation`] catches
//! that by presenting a known colour to a scratch canvas and reading the canvas back.

use std::sync::{Arc, Mutex};

use wasm_bindgen::{JsCast, JsValue};
use web_sys::HtmlCanvasElement;

use crate::error::{ActiveBackend, ViewerError};

/// What the device reported asynchronously.
#[derive(Debug, Default)]
pub(crate) struct GpuHealth {
    lost: Mutex<Option<String>>,
    errors: Mutex<Vec<String>>,
}

impl GpuHealth {
    /// Why the device was lost, if it was.
    pub(crate) fn lost(&self) -> Option<String> {
        self.lost.lock().ok().and_then(|l| l.clone())
    }

    /// Uncaptured errors since the last call.
    pub(crate) fn take_errors(&self) -> Vec<String> {
        self.errors.lock().map(|mut e| std::mem::take(&mut *e)).unwrap_or_default()
    }
}

/// A device and everything needed to make surfaces for it; the viewer keeps this alive for as
/// long as it draws (dropping the device can destroy it).
pub(crate) struct Gpu {
    pub instance: wgpu::Instance,
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub backend: ActiveBackend,
    pub health: Arc<GpuHealth>,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu").field("backend", &self.backend).field("adapter", &self.adapter.get_info().name).finish()
    }
}

fn instance(backends: wgpu::Backends) -> wgpu::Instance {
    let mut descriptor = wgpu::InstanceDescriptor::new_without_display_handle();
    descriptor.backends = backends;
    wgpu::Instance::new(descriptor)
}

async fn open_device(
    instance: wgpu::Instance,
    adapter: wgpu::Adapter,
    backend: ActiveBackend,
) -> Result<Gpu, wgpu::RequestDeviceError> {
    let (device, queue) = adapter
        .request_device(&wgpu::DeviceDescriptor {
            label: Some("egoexo viewer"),
            required_limits: wgpu::Limits::downlevel_webgl2_defaults().using_resolution(adapter.limits()),
            ..Default::default()
        })
        .await?;
    let health = Arc::new(GpuHealth::default());
    let on_lost = health.clone();
    device.set_device_lost_callback(move |reason, message| {
        if let Ok(mut lost) = on_lost.lost.lock() {
            *lost = Some(format!("{reason:?}: {message}"));
        }
    });
    let on_error = health.clone();
    // wgpu's default handler panics, which would kill the page's module.
    device.on_uncaptured_error(Arc::new(move |error: wgpu::Error| {
        let message = error.to_string();
        web_sys::console::error_1(&format!("egoexo viewer: GPU error: {message}").into());
        if let Ok(mut errors) = on_error.errors.lock()
            && errors.len() < 32
        {
            errors.push(message);
        }
    }));
    Ok(Gpu { instance, adapter, device, queue, backend, health })
}

/// A WebGPU device (no surface yet). Fails when the browser has no `navigator.gpu`, no adapter
/// or no device.
pub(crate) async fn webgpu() -> Result<Gpu, ViewerError> {
    let has_gpu = web_sys::window()
        .map(|w| js_sys::Reflect::has(&w.navigator(), &"gpu".into()).unwrap_or(false))
        .unwrap_or(false);
    if !has_gpu {
        return Err(ViewerError::NoWebGpu("navigator.gpu is missing (browser without WebGPU)".into()));
    }
    let instance = instance(wgpu::Backends::BROWSER_WEBGPU);
    let adapter = instance
        .request_adapter(&wgpu::RequestAdapterOptions::default())
        .await
        .map_err(|e| ViewerError::NoWebGpu(format!("no adapter ({e})")))?;
    if adapter.get_info().backend != wgpu::Backend::BrowserWebGpu {
        return Err(ViewerError::NoWebGpu(format!(
            "adapter is {:?}, not the browser's WebGPU",
            adapter.get_info().backend
        )));
    }
    open_device(instance, adapter, ActiveBackend::WebGpu)
        .await
        .map_err(|e| ViewerError::NoWebGpu(format!("no device ({e})")))
}

/// A WebGL2 device with its surface on `canvas` (WebGL2 adapters only come from a surface).
/// Fails when the canvas cannot give a `webgl2` context, e.g. because it already has another
/// kind of context.
pub(crate) async fn webgl2(canvas: &HtmlCanvasElement) -> Result<(Gpu, wgpu::Surface<'static>), ViewerError> {
    let instance = instance(wgpu::Backends::GL);
    let surface = instance
        .create_surface(wgpu::SurfaceTarget::Canvas(canvas.clone()))
        .map_err(|e| ViewerError::NoWebGl2(format!("no webgl2 context on the canvas ({e})")))?;
    let adapter = instance
        .request_adapter(&wgpu::RequestAdapterOptions { compatible_surface: Some(&surface), ..Default::default() })
        .await
        .map_err(|e| ViewerError::NoWebGl2(format!("no adapter ({e})")))?;
    let gpu = open_device(instance, adapter, ActiveBackend::WebGl2)
        .await
        .map_err(|e| ViewerError::NoWebGl2(format!("no device ({e})")))?;
    Ok((gpu, surface))
}

/// A surface on `canvas` for a WebGPU device.
pub(crate) fn webgpu_surface(gpu: &Gpu, canvas: &HtmlCanvasElement) -> Result<wgpu::Surface<'static>, ViewerError> {
    gpu.instance
        .create_surface(wgpu::SurfaceTarget::Canvas(canvas.clone()))
        .map_err(|e| ViewerError::WebGpuCannotPresent(format!("no webgpu context on the canvas ({e})")))
}

/// Configures `surface` for `width × height` pixels: a non-sRGB format when offered (the
/// shaders output display-encoded colour), opaque compositing, vsync.
pub(crate) fn configure_surface(
    gpu: &Gpu,
    surface: &wgpu::Surface<'_>,
    width: u32,
    height: u32,
) -> Result<wgpu::SurfaceConfiguration, ViewerError> {
    let caps = surface.get_capabilities(&gpu.adapter);
    let format = caps
        .formats
        .iter()
        .copied()
        .find(|f| !f.is_srgb())
        .or_else(|| caps.formats.first().copied())
        .ok_or_else(|| ViewerError::Gpu(format!("the {} surface offers no format", gpu.backend.as_str())))?;
    let alpha_mode = if caps.alpha_modes.contains(&wgpu::CompositeAlphaMode::Opaque) {
        wgpu::CompositeAlphaMode::Opaque
    } else {
        caps.alpha_modes.first().copied().unwrap_or(wgpu::CompositeAlphaMode::Auto)
    };
    let present_mode = if caps.present_modes.contains(&wgpu::PresentMode::Fifo) {
        wgpu::PresentMode::Fifo
    } else {
        caps.present_modes.first().copied().unwrap_or(wgpu::PresentMode::AutoVsync)
    };
    let config = wgpu::SurfaceConfiguration {
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
        format,
        color_space: wgpu::SurfaceColorSpace::Auto,
        width: width.max(1),
        height: height.max(1),
        present_mode,
        desired_maximum_frame_latency: 2,
        alpha_mode,
        view_formats: vec![],
    };
    surface.configure(&gpu.device, &config);
    Ok(config)
}

/// Whether the adapter can multisample `format` 4×.
pub(crate) fn msaa_supported(gpu: &Gpu, format: wgpu::TextureFormat) -> bool {
    gpu.adapter.get_texture_format_features(format).flags.sample_count_supported(4)
}

/// The largest texture side the device accepts, pixels.
pub(crate) fn max_texture_side(gpu: &Gpu) -> u32 {
    gpu.device.limits().max_texture_dimension_2d
}

/// A promise that resolves after `ms` milliseconds (the browser's event loop keeps running).
pub(crate) async fn sleep_ms(ms: i32) {
    let promise = js_sys::Promise::new(&mut |resolve, _| {
        let scheduled = web_sys::window()
            .map(|w| w.set_timeout_with_callback_and_timeout_and_arguments_0(&resolve, ms).is_ok())
            .unwrap_or(false);
        if !scheduled {
            let _ = resolve.call0(&JsValue::NULL);
        }
    });
    let _ = wasm_bindgen_futures::JsFuture::from(promise).await;
}

/// The colour the presentation probe clears to (RGB, 0..=255).
const PROBE_RGB: [u8; 3] = [26, 179, 77];

/// Checks that WebGPU really reaches the screen: clears a scratch canvas to a known colour,
/// presents it, lets the compositor run, and reads the canvas back through a 2D canvas; the
/// device must not be lost and no error raised meanwhile. `Err` says what went wrong.
pub(crate) async fn probe_webgpu_presentation(gpu: &Gpu) -> Result<(), String> {
    const SIDE: u32 = 8;
    let scratch = scratch_canvas(SIDE, SIDE).map_err(|e| e.to_string())?;
    let surface = webgpu_surface(gpu, &scratch).map_err(|e| e.to_string())?;
    let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let config = configure_surface(gpu, &surface, SIDE, SIDE).map_err(|e| e.to_string())?;
    let frame = match surface.get_current_texture() {
        wgpu::CurrentSurfaceTexture::Success(t) | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
        _ => {
            drop(scope);
            return Err("the canvas gave no texture to draw into".into());
        }
    };
    let view = frame.texture.create_view(&Default::default());
    let channel = |c: u8| {
        let c = f64::from(c) / 255.0;
        if config.format.is_srgb() { c.powf(2.2) } else { c }
    };
    let clear = wgpu::Color { r: channel(PROBE_RGB[0]), g: channel(PROBE_RGB[1]), b: channel(PROBE_RGB[2]), a: 1.0 };
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
        label: Some("presentation probe"),
        color_attachments: &[Some(wgpu::RenderPassColorAttachment {
            view: &view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(clear), store: wgpu::StoreOp::Store },
        })],
        ..Default::default()
    });
    gpu.queue.submit([encoder.finish()]);
    gpu.queue.present(frame);
    if let Some(error) = scope.pop().await {
        return Err(format!("presenting raised an error: {error}"));
    }
    // Presentation happens when the page updates its rendering; a failure arrives later as a
    // lost device. Give it a few frames.
    for _ in 0..6 {
        sleep_ms(25).await;
        if let Some(lost) = gpu.health.lost() {
            return Err(format!("the device was lost after presenting ({lost})"));
        }
    }
    if let Some(error) = gpu.health.take_errors().into_iter().next() {
        return Err(format!("presenting raised an error: {error}"));
    }
    let pixel = canvas_pixel(&scratch, SIDE / 2, SIDE / 2).map_err(|e| e.to_string())?;
    let close = pixel.iter().zip(PROBE_RGB).all(|(&got, want)| got.abs_diff(want) <= 8) && pixel[3] == 255;
    if !close {
        return Err(format!(
            "the canvas shows RGBA {pixel:?} instead of the presented {PROBE_RGB:?} (presentation does not reach it)"
        ));
    }
    Ok(())
}

fn document() -> Result<web_sys::Document, ViewerError> {
    web_sys::window().and_then(|w| w.document()).ok_or_else(|| ViewerError::Dom("no window.document".into()))
}

fn js_message(e: JsValue) -> String {
    e.dyn_ref::<js_sys::Error>().map(|e| String::from(e.message())).unwrap_or_else(|| format!("{e:?}"))
}

/// A detached canvas of `width × height` pixels.
pub(crate) fn scratch_canvas(width: u32, height: u32) -> Result<HtmlCanvasElement, ViewerError> {
    let canvas: HtmlCanvasElement = document()?
        .create_element("canvas")
        .map_err(|e| ViewerError::Dom(js_message(e)))?
        .dyn_into()
        .map_err(|_| ViewerError::Dom("createElement(\"canvas\") gave no canvas".into()))?;
    canvas.set_width(width);
    canvas.set_height(height);
    Ok(canvas)
}

/// RGBA of pixel `(x, y)` of any canvas (WebGPU, WebGL2 or 2D), read by drawing it into a 2D
/// canvas.
pub(crate) fn canvas_pixel(canvas: &HtmlCanvasElement, x: u32, y: u32) -> Result<[u8; 4], ViewerError> {
    let rgba = canvas_rgba(canvas)?;
    let i = 4 * (y as usize * canvas.width() as usize + x as usize);
    rgba.get(i..i + 4)
        .map(|p| [p[0], p[1], p[2], p[3]])
        .ok_or_else(|| ViewerError::Dom(format!("pixel ({x}, {y}) is outside the canvas")))
}

/// All RGBA pixels of any canvas (rows top to bottom), read by drawing it into a 2D canvas.
pub(crate) fn canvas_rgba(canvas: &HtmlCanvasElement) -> Result<Vec<u8>, ViewerError> {
    let (w, h) = (canvas.width(), canvas.height());
    let copy = scratch_canvas(w, h)?;
    let context: web_sys::CanvasRenderingContext2d = copy
        .get_context("2d")
        .map_err(|e| ViewerError::Dom(js_message(e)))?
        .ok_or_else(|| ViewerError::Dom("no 2d context".into()))?
        .dyn_into()
        .map_err(|_| ViewerError::Dom("the 2d context is not a CanvasRenderingContext2D".into()))?;
    context.draw_image_with_html_canvas_element(canvas, 0.0, 0.0).map_err(|e| ViewerError::Dom(js_message(e)))?;
    let data = context.get_image_data(0, 0, w as i32, h as i32).map_err(|e| ViewerError::Dom(js_message(e)))?;
    Ok(data.data().0)
}

/// Copies `texture` (`width × height`, 4 bytes per pixel) to the CPU: tightly packed rows, top
/// to bottom. Polls the device until the copy is mapped (at most ~20 s).
pub(crate) async fn read_texture(
    gpu: &Gpu,
    texture: &wgpu::Texture,
    width: u32,
    height: u32,
) -> Result<Vec<u8>, ViewerError> {
    let unpadded = 4 * width;
    let padded = unpadded.next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read-back"),
        size: u64::from(padded) * u64::from(height),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = gpu.device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
    );
    gpu.queue.submit([encoder.finish()]);
    let mapped: Arc<Mutex<Option<Result<(), wgpu::BufferAsyncError>>>> = Arc::default();
    let done = mapped.clone();
    buffer.map_async(wgpu::MapMode::Read, .., move |result| {
        if let Ok(mut slot) = done.lock() {
            *slot = Some(result);
        }
    });
    for _ in 0..4000 {
        // WebGL2 needs polling to finish the map; WebGPU resolves it from the event loop.
        let _ = gpu.device.poll(wgpu::PollType::Poll);
        let state = mapped.lock().ok().and_then(|mut m| m.take());
        match state {
            Some(Ok(())) => {
                let view =
                    buffer.get_mapped_range(..).map_err(|e| ViewerError::Gpu(format!("read-back mapping: {e}")))?;
                let mut rgba = Vec::with_capacity((unpadded * height) as usize);
                for row in view.chunks(padded as usize).take(height as usize) {
                    rgba.extend_from_slice(&row[..unpadded as usize]);
                }
                drop(view);
                buffer.unmap();
                return Ok(rgba);
            }
            Some(Err(e)) => return Err(ViewerError::Gpu(format!("read-back failed: {e}"))),
            None => {}
        }
        if let Some(lost) = gpu.health.lost() {
            return Err(ViewerError::Gpu(format!("the device was lost during read-back ({lost})")));
        }
        sleep_ms(5).await;
    }
    Err(ViewerError::Gpu("read-back did not finish within 20 s".into()))
}
