//! The viewer in headless Chromium: off-screen renders on WebGPU and WebGL2 read back and
//! checked pixel by pixel against where the skeleton projects; a live viewer on a WebGL2
//! canvas read back through a 2D canvas; backend detection; keyboard, pointer and `on_frame`.
//!
//! `cargo xtask test` runs this with Chromium's `--enable-unsafe-webgpu
//! --enable-unsafe-swiftshader`, which give WebGPU a (software) adapter.

#![cfg(target_arch = "wasm32")]

use egoexo_core::skeleton::JOINT_NAMES;
use egoexo_scene::SceneData;
use egoexo_viewer::Viewer;
use egoexo_viewer::camera::OrbitCamera;
use egoexo_viewer::colors;
use egoexo_viewer::example::{example_joints, example_scene};
use egoexo_viewer::scene::view_bounds;
use glam::Vec3;
use wasm_bindgen::{JsCast, JsValue};
use wasm_bindgen_test::{wasm_bindgen_test, wasm_bindgen_test_configure};

wasm_bindgen_test_configure!(run_in_browser);

const W: u32 = 640;
const H: u32 = 480;
const FRAME: usize = 10;

/// The example scene without the translucent layers, so joint pixels keep their side colours.
fn plain_scene() -> SceneData {
    let mut scene = example_scene(30);
    scene.ground_truth_joints = None;
    scene.ego_only_joints = None;
    scene
}

fn json(scene: &SceneData) -> Vec<u8> {
    serde_json::to_vec(scene).expect("scene serialises")
}

fn message(e: impl Into<JsValue>) -> String {
    let v: JsValue = e.into();
    v.dyn_ref::<js_sys::Error>().map(|e| String::from(e.message())).unwrap_or_else(|| format!("{v:?}"))
}

struct Image {
    rgba: Vec<u8>,
    width: u32,
    height: u32,
}

impl Image {
    fn pixel(&self, x: i32, y: i32) -> Option<[u8; 4]> {
        if x < 0 || y < 0 || x >= self.width as i32 || y >= self.height as i32 {
            return None;
        }
        let i = 4 * (y as usize * self.width as usize + x as usize);
        Some([self.rgba[i], self.rgba[i + 1], self.rgba[i + 2], self.rgba[i + 3]])
    }

    /// Whether some pixel within `r` pixels of `(x, y)` satisfies `test`.
    fn any_near(&self, x: f32, y: f32, r: i32, test: impl Fn([u8; 4]) -> bool) -> bool {
        let (cx, cy) = (x.round() as i32, y.round() as i32);
        (-r..=r).any(|dy| (-r..=r).any(|dx| self.pixel(cx + dx, cy + dy).is_some_and(&test)))
    }

    fn count(&self, test: impl Fn([u8; 4]) -> bool) -> usize {
        self.rgba.chunks(4).filter(|p| test([p[0], p[1], p[2], p[3]])).count()
    }
}

/// Left-side blue (not the cyan of observer 1 or the gate ramp's green).
fn is_left_blue(p: [u8; 4]) -> bool {
    p[2] > 150 && i32::from(p[2]) > i32::from(p[0]) + 80 && f32::from(p[1]) < 0.8 * f32::from(p[2])
}

fn is_right_orange(p: [u8; 4]) -> bool {
    p[0] > 170 && i32::from(p[0]) > i32::from(p[2]) + 100
}

fn is_background(p: [u8; 4]) -> bool {
    let bg = colors::BACKGROUND.map(|c| (c * 255.0).round() as i32);
    (0..3).all(|i| (i32::from(p[i]) - bg[i]).abs() <= 4) && p[3] == 255
}

/// Where joint `j` of the example wearer at [`FRAME`] lands in the default view.
fn joint_pixel(scene: &SceneData, j: usize) -> (f32, f32) {
    let camera = OrbitCamera::framing(view_bounds(scene, FRAME).expect("scene has bounds"), W as f32 / H as f32);
    let p = camera.project(example_joints(FRAME)[j], W as f32, H as f32).expect("joint in front of the camera");
    (p.x, p.y)
}

fn joint(name: &str) -> usize {
    JOINT_NAMES.iter().position(|n| *n == name).expect("SMPL joint name")
}

/// The checks every render of the plain example must pass: left limbs blue and right limbs
/// orange where they project, background in the corners and beside the wearer.
fn assert_skeleton_drawn(image: &Image, scene: &SceneData, what: &str) {
    assert_eq!(image.rgba.len(), (4 * W * H) as usize, "{what}: RGBA size");
    for name in ["left_elbow", "left_wrist", "left_knee", "left_shoulder", "left_hand", "left_foot"] {
        let (x, y) = joint_pixel(scene, joint(name));
        assert!(
            image.any_near(x, y, 1, is_left_blue),
            "{what}: {name} at ({x:.0}, {y:.0}) is not left-coloured: {:?}",
            image.pixel(x as i32, y as i32)
        );
    }
    for name in ["right_elbow", "right_wrist", "right_knee", "right_shoulder", "right_hand", "right_foot"] {
        let (x, y) = joint_pixel(scene, joint(name));
        assert!(
            image.any_near(x, y, 1, is_right_orange),
            "{what}: {name} at ({x:.0}, {y:.0}) is not right-coloured: {:?}",
            image.pixel(x as i32, y as i32)
        );
    }
    // No side colour leaks (hands have no rays ending on them).
    let (x, y) = joint_pixel(scene, joint("left_hand"));
    assert!(!image.any_near(x, y, 1, is_right_orange), "{what}: orange at the left hand");
    let (x, y) = joint_pixel(scene, joint("right_hand"));
    assert!(!image.any_near(x, y, 1, is_left_blue), "{what}: blue at the right hand");
    for (x, y) in [(3, 3), (W as i32 - 4, 3)] {
        assert!(is_background(image.pixel(x, y).unwrap()), "{what}: corner ({x}, {y}) is {:?}", image.pixel(x, y));
    }
    // Half a metre above the head there is nothing but background.
    let camera = OrbitCamera::framing(view_bounds(scene, FRAME).unwrap(), W as f32 / H as f32);
    let above = camera.project(example_joints(FRAME)[15] + Vec3::Y * 0.5, W as f32, H as f32).unwrap();
    assert!(
        image.any_near(above.x, above.y, 0, is_background),
        "{what}: above the head is {:?}",
        image.pixel(above.x as i32, above.y as i32)
    );
    // Skeleton colours cover a plausible area, not the whole image.
    let skeleton = image.count(|p| is_left_blue(p) || is_right_orange(p));
    assert!(skeleton > 150 && skeleton < (W * H / 10) as usize, "{what}: {skeleton} skeleton pixels");
}

async fn offscreen(scene: &SceneData, frame: usize, backend: &str) -> Result<Image, String> {
    let rgba = Viewer::render_offscreen(json(scene), frame as f64, W, H, backend.to_string()).await.map_err(message)?;
    Ok(Image { rgba: rgba.to_vec(), width: W, height: H })
}

#[wasm_bindgen_test]
async fn webgpu_offscreen_render_shows_the_skeleton() {
    let scene = plain_scene();
    let image =
        offscreen(&scene, FRAME, "webgpu").await.expect("WebGPU renders off-screen (needs --enable-unsafe-webgpu)");
    assert_skeleton_drawn(&image, &scene, "webgpu off-screen");
}

#[wasm_bindgen_test]
async fn webgl2_offscreen_render_shows_the_skeleton_and_matches_webgpu() {
    let scene = plain_scene();
    let gl = offscreen(&scene, FRAME, "webgl2").await.expect("WebGL2 renders off-screen");
    assert_skeleton_drawn(&gl, &scene, "webgl2 off-screen");
    let gpu = offscreen(&scene, FRAME, "webgpu").await.expect("WebGPU renders off-screen");
    // Same scene, same camera: the two backends agree on almost every pixel.
    let differing = gl
        .rgba
        .chunks(4)
        .zip(gpu.rgba.chunks(4))
        .filter(|(a, b)| a.iter().zip(b.iter()).any(|(x, y)| x.abs_diff(*y) > 40));
    let differing = differing.count();
    assert!(differing < (W * H / 100) as usize, "{differing} pixels differ between WebGL2 and WebGPU");
}

#[wasm_bindgen_test]
async fn frames_without_a_reconstruction_are_dimmed() {
    let mut scene = plain_scene();
    scene.valid[FRAME] = false;
    // Gate-coloured rays end on the joints; leave only the skeleton and devices.
    scene.observers.clear();
    let image = offscreen(&scene, FRAME, "auto").await.expect("renders");
    for name in ["left_elbow", "right_elbow", "left_knee", "right_knee", "left_hand", "right_foot"] {
        let (x, y) = joint_pixel(&scene, joint(name));
        assert!(!image.any_near(x, y, 1, |p| is_left_blue(p) || is_right_orange(p)), "{name} is drawn at full colour");
        assert!(image.any_near(x, y, 1, |p| !is_background(p)), "{name} is not drawn at all");
    }
}

fn is_green(p: [u8; 4]) -> bool {
    p[1] > 100 && i32::from(p[1]) > i32::from(p[0]) + 50 && i32::from(p[1]) > i32::from(p[2]) + 50
}

fn is_red(p: [u8; 4]) -> bool {
    p[0] > 100 && i32::from(p[0]) > i32::from(p[1]) + 50 && i32::from(p[0]) > i32::from(p[2]) + 50
}

/// The ego-only overlay's violet.
fn is_violet(p: [u8; 4]) -> bool {
    p[0] > 120 && p[2] > 160 && i32::from(p[1]) + 40 < i32::from(p[0])
}

#[wasm_bindgen_test]
async fn layers_toggle_rays_in_gate_colours_and_the_ego_only_overlay() {
    let mut scene = plain_scene();
    scene.ego_only_joints = example_scene(30).ego_only_joints;
    let camera = OrbitCamera::framing(view_bounds(&scene, FRAME).unwrap(), W as f32 / H as f32);
    let observer = egoexo_viewer::example::EXAMPLE_OBSERVER_POSITION;
    // Midpoints of the rays to the right ankle (gate 1: green) and to the nose (gate 0: red).
    let rays = &scene.observers[0].rays[4 * 13 * FRAME..4 * 13 * (FRAME + 1)];
    let end = |k: usize| Vec3::new(rays[4 * k], rays[4 * k + 1], rays[4 * k + 2]);
    let green = camera.project(observer.lerp(end(12), 0.5), W as f32, H as f32).unwrap();
    let red = camera.project(observer.lerp(end(0), 0.5), W as f32, H as f32).unwrap();

    let viewer = canvas_viewer("layers-canvas", "webgl2").await.unwrap();
    viewer.set_scene_json(&json(&scene)).map_err(message).unwrap();
    viewer.seek(FRAME as f64).map_err(message).unwrap();
    assert!(viewer.has_ego_only() && !viewer.has_ground_truth());
    let image = read_canvas(&viewer);
    let around = |image: &Image, x: f32, y: f32| -> Vec<[u8; 4]> {
        (-2..=2).flat_map(|dy| (-2..=2).filter_map(move |dx| image.pixel(x as i32 + dx, y as i32 + dy))).collect()
    };
    assert!(
        image.any_near(green.x, green.y, 2, is_green),
        "no green ray near {green}: {:?}",
        around(&image, green.x, green.y)
    );
    assert!(image.any_near(red.x, red.y, 2, is_red), "no red ray near {red}: {:?}", around(&image, red.x, red.y));
    assert_eq!(image.count(is_violet), 0, "the ego-only overlay is off by default");

    viewer.set_show_rays(false).map_err(message).unwrap();
    viewer.set_show_ego_only(true).map_err(message).unwrap();
    let image = read_canvas(&viewer);
    assert!(!image.any_near(green.x, green.y, 2, is_green), "rays still drawn: {:?}", around(&image, green.x, green.y));
    assert!(!image.any_near(red.x, red.y, 2, is_red), "rays still drawn");
    assert!(image.count(is_violet) > 50, "the ego-only overlay is not drawn");
    drop(viewer);
}

#[wasm_bindgen_test]
async fn offscreen_rejects_bad_input_with_messages() {
    let scene = plain_scene();
    let err = Viewer::render_offscreen(b"{not json".to_vec(), 0.0, 8, 8, "auto".into()).await.unwrap_err();
    assert!(message(err).contains("scene JSON is not a SceneData"));
    let err = Viewer::render_offscreen(json(&scene), 0.0, 0, 8, "auto".into()).await.unwrap_err();
    assert!(message(err).contains("0×8"));
    let err = Viewer::render_offscreen(json(&scene), f64::NAN, 8, 8, "auto".into()).await.unwrap_err();
    assert!(message(err).contains("finite"));
    let err = Viewer::render_offscreen(json(&scene), 0.0, 8, 8, "vulkan".into()).await.unwrap_err();
    assert!(message(err).contains("\"vulkan\""));
}

fn attached_canvas(id: &str) -> web_sys::HtmlCanvasElement {
    let document = web_sys::window().unwrap().document().unwrap();
    let canvas: web_sys::HtmlCanvasElement = document.create_element("canvas").unwrap().dyn_into().unwrap();
    canvas.set_id(id);
    canvas.set_class_name("view");
    canvas.set_attribute("style", &format!("width: {W}px; height: {H}px; display: block")).unwrap();
    document.body().unwrap().append_child(&canvas).unwrap();
    canvas
}

/// The canvas's pixels, read through a 2D canvas right after a synchronous draw.
fn read_canvas(viewer: &Viewer) -> Image {
    viewer.render_now().map_err(message).expect("draws");
    let canvas = viewer.canvas().expect("a canvas");
    let (width, height) = (canvas.width(), canvas.height());
    let document = web_sys::window().unwrap().document().unwrap();
    let copy: web_sys::HtmlCanvasElement = document.create_element("canvas").unwrap().dyn_into().unwrap();
    copy.set_width(width);
    copy.set_height(height);
    let context: web_sys::CanvasRenderingContext2d = copy.get_context("2d").unwrap().unwrap().dyn_into().unwrap();
    context.draw_image_with_html_canvas_element(&canvas, 0.0, 0.0).unwrap();
    let data = context.get_image_data(0, 0, width as i32, height as i32).unwrap();
    Image { rgba: data.data().0, width, height }
}

async fn canvas_viewer(id: &str, backend: &str) -> Result<Viewer, String> {
    let viewer = Viewer::create(attached_canvas(id), backend.to_string()).await.map_err(message)?;
    viewer.resize(f64::from(W), f64::from(H), 1.0).map_err(message)?;
    Ok(viewer)
}

#[wasm_bindgen_test]
async fn webgl2_canvas_shows_the_skeleton() {
    let scene = plain_scene();
    let viewer = canvas_viewer("webgl2-canvas", "webgl2").await.expect("a WebGL2 viewer");
    assert_eq!(viewer.backend(), "webgl2");
    viewer.set_scene_json(&json(&scene)).map_err(message).unwrap();
    assert_eq!(viewer.seek(FRAME as f64).map_err(message).unwrap(), FRAME);
    let image = read_canvas(&viewer);
    assert_eq!((image.width, image.height), (W, H));
    assert_skeleton_drawn(&image, &scene, "webgl2 canvas");
    // The canvas path and the off-screen path draw the same picture.
    let offscreen = offscreen(&scene, FRAME, "webgl2").await.unwrap();
    let differing = image
        .rgba
        .chunks(4)
        .zip(offscreen.rgba.chunks(4))
        .filter(|(a, b)| a.iter().zip(b.iter()).any(|(x, y)| x.abs_diff(*y) > 40));
    let differing = differing.count();
    assert!(differing < (W * H / 200) as usize, "{differing} pixels differ from the off-screen render");
    assert_eq!(viewer.failure(), None);
    drop(viewer);
}

#[wasm_bindgen_test]
async fn auto_falls_back_to_a_canvas_that_really_shows_the_scene() {
    let scene = plain_scene();
    let canvas = attached_canvas("auto-canvas");
    let viewer =
        Viewer::create(canvas.clone(), "auto".into()).await.map_err(message).expect("auto always gets a backend");
    viewer.resize(f64::from(W), f64::from(H), 1.0).map_err(message).unwrap();
    let backend = viewer.backend();
    web_sys::console::log_1(&format!("auto chose {backend}").into());
    // Headless Chromium renders WebGPU off-screen but cannot present it to a canvas: the
    // probe must notice and choose WebGL2 on the page's own canvas.
    assert_eq!(backend, "webgl2", "headless Chromium cannot present WebGPU; auto must fall back");
    let used = viewer.canvas().unwrap();
    assert!(used == canvas, "the page's canvas is kept when it was never given a WebGPU context");
    viewer.set_scene_json(&json(&scene)).map_err(message).unwrap();
    viewer.seek(FRAME as f64).map_err(message).unwrap();
    assert_skeleton_drawn(&read_canvas(&viewer), &scene, "auto canvas");
    drop(viewer);
}

#[wasm_bindgen_test]
async fn forced_webgpu_on_a_canvas_reports_that_it_cannot_present() {
    match Viewer::create(attached_canvas("webgpu-canvas"), "webgpu".into()).await {
        Ok(viewer) => {
            // A browser that can present: then the canvas must show the scene.
            assert_eq!(viewer.backend(), "webgpu");
            let scene = plain_scene();
            viewer.resize(f64::from(W), f64::from(H), 1.0).map_err(message).unwrap();
            viewer.set_scene_json(&json(&scene)).map_err(message).unwrap();
            viewer.seek(FRAME as f64).map_err(message).unwrap();
            viewer.render_now().map_err(message).unwrap();
            panic!("headless Chromium presented WebGPU to a canvas; update the backend notes");
        }
        Err(e) => {
            let msg = message(e);
            assert!(msg.contains("WebGPU cannot present to a canvas"), "{msg}");
        }
    }
}

#[wasm_bindgen_test]
async fn a_webgpu_device_lost_while_drawing_falls_back_to_webgl2_in_place() {
    // Skip the presentation check: headless Chromium then loses the device when the viewer
    // presents, and the viewer must switch to WebGL2 on a fresh canvas by itself.
    let canvas = attached_canvas("lost-canvas");
    let viewer =
        Viewer::create(canvas.clone(), "webgpu-unchecked".into()).await.map_err(message).expect("a WebGPU device");
    assert_eq!(viewer.backend(), "webgpu");
    let scene = plain_scene();
    viewer.resize(f64::from(W), f64::from(H), 1.0).map_err(message).unwrap();
    viewer.set_scene_json(&json(&scene)).map_err(message).unwrap();
    viewer.seek(FRAME as f64).map_err(message).unwrap();
    for _ in 0..100 {
        if viewer.backend() == "webgl2" {
            break;
        }
        sleep_ms(50).await;
    }
    assert_eq!(viewer.backend(), "webgl2", "no fallback after the device was lost ({:?})", viewer.failure());
    let used = viewer.canvas().unwrap();
    assert!(used != canvas && used.id() == "lost-canvas" && used.parent_node().is_some());
    assert_eq!((viewer.frame(), viewer.frames()), (FRAME, 30), "the scene and timeline survive the switch");
    assert_skeleton_drawn(&read_canvas(&viewer), &scene, "after the fallback");
    assert_eq!(viewer.failure(), None);
    drop(viewer);
}

#[wasm_bindgen_test]
async fn a_canvas_that_held_webgpu_is_replaced_for_webgl2() {
    let canvas = attached_canvas("used-canvas");
    // Give the canvas a WebGPU context first, as a previous viewer would have.
    let context = canvas.get_context("webgpu").ok().flatten();
    assert!(context.is_some(), "Chromium gives a webgpu context with --enable-unsafe-webgpu");
    let viewer =
        Viewer::create(canvas.clone(), "webgl2".into()).await.map_err(message).expect("WebGL2 on a fresh canvas");
    let used = viewer.canvas().unwrap();
    assert!(used != canvas, "a fresh canvas replaces one that holds a WebGPU context");
    assert_eq!(used.id(), "used-canvas");
    assert_eq!(used.class_name(), "view");
    assert!(canvas.parent_node().is_none() && used.parent_node().is_some());
    let scene = plain_scene();
    viewer.resize(f64::from(W), f64::from(H), 1.0).map_err(message).unwrap();
    viewer.set_scene_json(&json(&scene)).map_err(message).unwrap();
    viewer.seek(FRAME as f64).map_err(message).unwrap();
    assert_skeleton_drawn(&read_canvas(&viewer), &scene, "replacement canvas");
    drop(viewer);
}

fn key(key: &str, shift: bool) {
    let init = web_sys::KeyboardEventInit::new();
    init.set_key(key);
    init.set_shift_key(shift);
    init.set_bubbles(true);
    init.set_cancelable(true);
    let event = web_sys::KeyboardEvent::new_with_keyboard_event_init_dict("keydown", &init).unwrap();
    web_sys::window().unwrap().dispatch_event(&event).unwrap();
}

#[wasm_bindgen_test]
async fn keys_playback_and_on_frame_drive_the_timeline() {
    let viewer = canvas_viewer("keys-canvas", "webgl2").await.unwrap();
    assert_eq!(viewer.frames(), 0);
    viewer.set_scene_json(&json(&example_scene(90))).map_err(message).unwrap();
    assert_eq!((viewer.frames(), viewer.frame(), viewer.fps()), (90, 0, 30.0));

    let seen = std::rc::Rc::new(std::cell::RefCell::new(Vec::<(f64, f64)>::new()));
    let sink = seen.clone();
    let callback = wasm_bindgen::closure::Closure::<dyn FnMut(f64, f64)>::new(move |frame, time| {
        sink.borrow_mut().push((frame, time));
    });
    viewer.on_frame(callback.as_ref().unchecked_ref::<js_sys::Function>().clone()).map_err(message).unwrap();
    assert_eq!(seen.borrow().last(), Some(&(0.0, 0.0)), "called once on registration");

    key("ArrowRight", false);
    assert_eq!(viewer.frame(), 1);
    key("ArrowRight", true);
    assert_eq!(viewer.frame(), 31);
    key("ArrowLeft", false);
    assert_eq!(viewer.frame(), 30);
    assert_eq!(seen.borrow().last(), Some(&(30.0, 1.0)));
    key("End", false);
    assert_eq!(viewer.frame(), 89);
    key("Home", false);
    assert_eq!(viewer.frame(), 0);
    assert!(!viewer.is_playing());
    let calls = seen.borrow().len();
    key(" ", false);
    assert!(viewer.is_playing());
    key(" ", false);
    assert!(!viewer.is_playing());
    assert_eq!(seen.borrow().len(), calls + 2, "play/pause is reported so a play button can follow");

    // Playback advances on animation frames, never faster than the chosen speed. (How soon
    // frames come is the machine's: on a loaded one they come late, so this waits for them
    // rather than for a fixed time.)
    viewer.set_speed(4.0).map_err(message).unwrap();
    let started_ms = js_sys::Date::now();
    viewer.play().map_err(message).unwrap();
    let before = seen.borrow().len();
    while viewer.frame() <= 10 && js_sys::Date::now() - started_ms < 20_000.0 {
        sleep_ms(50).await;
    }
    let elapsed_s = (js_sys::Date::now() - started_ms) / 1000.0;
    let during: Vec<f64> = seen.borrow()[before..].iter().map(|(frame, _)| *frame).collect();
    let frame = viewer.frame();
    viewer.pause().map_err(message).unwrap();
    assert!(frame > 10, "4× playback for {elapsed_s:.1} s moved only to frame {frame}");
    assert!(frame as f64 <= 4.0 * 30.0 * elapsed_s + 1.0, "{frame} frames in {elapsed_s:.2} s is faster than 4×");
    web_sys::console::log_1(&format!("{elapsed_s:.2} s of 4× playback: frame {frame}, on_frame saw {during:?}").into());
    assert!(!during.is_empty() && during.iter().all(|&f| f > 0.0), "on_frame follows playback: {during:?}");
    assert_eq!(during.last(), Some(&(frame as f64)));
    assert_eq!(seen.borrow().last().unwrap().0, frame as f64, "pausing reports the frame it stopped on");

    // Bad requests throw clear errors and change nothing.
    assert!(message(viewer.set_speed(f64::NAN).unwrap_err()).contains("speed"));
    assert!(message(viewer.seek(f64::INFINITY).unwrap_err()).contains("finite"));
    assert!(message(viewer.step(0.5).unwrap_err()).contains("whole"));
    assert!(message(viewer.resize(0.0, 10.0, 1.0).unwrap_err()).contains("css_width"));
    let mut broken = example_scene(5);
    broken.observers[0].rays.pop();
    let err = message(viewer.set_scene_json(&json(&broken)).unwrap_err());
    assert!(err.contains("observer observer-1 rays has 259 values, expected 260"), "{err}");
    assert_eq!(viewer.frames(), 90, "a refused scene keeps the current one");
    assert_eq!(viewer.frame(), frame);

    // Keys typed into a form field are the page's.
    let document = web_sys::window().unwrap().document().unwrap();
    let input: web_sys::HtmlElement = document.create_element("input").unwrap().dyn_into().unwrap();
    document.body().unwrap().append_child(&input).unwrap();
    let init = web_sys::KeyboardEventInit::new();
    init.set_key("ArrowRight");
    init.set_bubbles(true);
    let event = web_sys::KeyboardEvent::new_with_keyboard_event_init_dict("keydown", &init).unwrap();
    input.dispatch_event(&event).unwrap();
    assert_eq!(viewer.frame(), frame);
    input.remove();
    drop(viewer);
    drop(callback);
}

fn pointer(canvas: &web_sys::HtmlCanvasElement, kind: &str, x: f64, y: f64, button: i16) {
    let init = web_sys::PointerEventInit::new();
    init.set_pointer_id(7);
    init.set_client_x(x as i32);
    init.set_client_y(y as i32);
    init.set_button(button);
    init.set_bubbles(true);
    init.set_cancelable(true);
    let event = web_sys::PointerEvent::new_with_event_init_dict(kind, &init).unwrap();
    canvas.dispatch_event(&event).unwrap();
}

#[wasm_bindgen_test]
async fn dragging_orbits_and_the_wheel_zooms() {
    let scene = plain_scene();
    let viewer = canvas_viewer("drag-canvas", "webgl2").await.unwrap();
    viewer.set_scene_json(&json(&scene)).map_err(message).unwrap();
    viewer.seek(FRAME as f64).map_err(message).unwrap();
    let canvas = viewer.canvas().unwrap();
    let skeleton_pixels = |image: &Image| image.count(|p| is_left_blue(p) || is_right_orange(p));
    let start = read_canvas(&viewer);

    // Orbit half a turn around: the wearer's left now appears on the image's right.
    let (lx, _) = joint_pixel(&scene, joint("left_wrist"));
    let (rx, _) = joint_pixel(&scene, joint("right_wrist"));
    assert!(lx > rx, "default view: the wearer faces the camera");
    pointer(&canvas, "pointerdown", 100.0, 100.0, 0);
    pointer(&canvas, "pointermove", 100.0 + std::f64::consts::PI / 0.006, 100.0, 0);
    pointer(&canvas, "pointerup", 100.0 + std::f64::consts::PI / 0.006, 100.0, 0);
    let turned = read_canvas(&viewer);
    let mean_x = |image: &Image, test: fn([u8; 4]) -> bool| {
        let xs: Vec<f32> = image
            .rgba
            .chunks(4)
            .enumerate()
            .filter(|(_, p)| test([p[0], p[1], p[2], p[3]]))
            .map(|(i, _)| (i % W as usize) as f32)
            .collect();
        xs.iter().sum::<f32>() / xs.len().max(1) as f32
    };
    assert!(mean_x(&start, is_left_blue) > mean_x(&start, is_right_orange));
    assert!(mean_x(&turned, is_left_blue) < mean_x(&turned, is_right_orange), "orbiting did not turn the view");

    // Zooming out shrinks the skeleton on screen; double-click re-frames.
    viewer.reset_camera().map_err(message).unwrap();
    let framed = skeleton_pixels(&read_canvas(&viewer));
    let init = web_sys::WheelEventInit::new();
    init.set_delta_y(400.0);
    init.set_cancelable(true);
    let wheel = web_sys::WheelEvent::new_with_event_init_dict("wheel", &init).unwrap();
    canvas.dispatch_event(&wheel).unwrap();
    assert!(wheel.default_prevented(), "the page does not scroll while zooming");
    let zoomed_out = skeleton_pixels(&read_canvas(&viewer));
    assert!(zoomed_out * 2 < framed, "zooming out: {framed} → {zoomed_out} skeleton pixels");
    let dblclick = web_sys::MouseEvent::new("dblclick").unwrap();
    canvas.dispatch_event(&dblclick).unwrap();
    assert_eq!(skeleton_pixels(&read_canvas(&viewer)), framed);
    drop(viewer);
}

async fn sleep_ms(ms: i32) {
    let promise = js_sys::Promise::new(&mut |resolve, _| {
        web_sys::window().unwrap().set_timeout_with_callback_and_timeout_and_arguments_0(&resolve, ms).unwrap();
    });
    wasm_bindgen_futures::JsFuture::from(promise).await.unwrap();
}
