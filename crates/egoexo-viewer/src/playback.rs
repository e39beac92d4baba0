//! Playback state of the timeline: which frame is shown, whether it advances, how fast.
//!
//! Time is the scene's frame clock: frame `i` is shown at `i / fps` seconds after the first
//! frame. The position is kept as a fractional frame so that slow speeds advance smoothly;
//! the shown frame is its integer part. Playback loops: past the last frame it wraps to 0.

use thiserror::Error;

/// Slowest and fastest playback speeds accepted by [`Playback::set_speed`] (× real time).
pub const SPEED_RANGE: (f64, f64) = (0.05, 16.0);

/// Longest wall-clock step [`Playback::advance`] takes in one call, seconds: after a hidden tab
/// or a debugger pause the animation resumes instead of jumping far ahead.
pub const MAX_ADVANCE_S: f64 = 0.25;

/// A playback request the state refuses.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum PlaybackError {
    #[error("playback speed must be a finite number in [{min}, {max}] (× real time), got {0}", min = SPEED_RANGE.0, max = SPEED_RANGE.1)]
    BadSpeed(f64),
    #[error("frame to seek to must be a finite number, got {0}")]
    BadFrame(f64),
    #[error("frame step must be a finite whole number, got {0}")]
    BadStep(f64),
    #[error("seek offset must be a finite number of seconds, got {0}")]
    BadSeconds(f64),
}

/// The timeline state of the viewer.
#[derive(Clone, Debug, PartialEq)]
pub struct Playback {
    frames: usize,
    fps: f64,
    /// Fractional frame position, in `0..frames` (0 when there are no frames).
    position: f64,
    playing: bool,
    speed: f64,
    /// Frames `start..=end` played in a loop, if set.
    loop_range: Option<(usize, usize)>,
}

impl Playback {
    /// A paused timeline at frame 0 of `frames` frames at `fps` frames per second (a non-finite
    /// or non-positive `fps` is treated as 30; scenes are validated before they get here).
    pub fn new(frames: usize, fps: f64) -> Self {
        let fps = if fps.is_finite() && fps > 0.0 { fps } else { 30.0 };
        Self { frames, fps, position: 0.0, playing: false, speed: 1.0, loop_range: None }
    }

    /// Number of frames on the timeline.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// Frames per second of the scene clock.
    pub fn fps(&self) -> f64 {
        self.fps
    }

    /// The frame shown now (`0` when there are no frames).
    pub fn frame(&self) -> usize {
        if self.frames == 0 { 0 } else { (self.position.floor() as usize).min(self.frames - 1) }
    }

    /// Seconds from the first frame to the shown one.
    pub fn time_s(&self) -> f64 {
        self.frame() as f64 / self.fps
    }

    pub fn is_playing(&self) -> bool {
        self.playing
    }

    /// Playback speed, × real time.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// Starts advancing (a timeline with fewer than two frames stays put but reports playing).
    pub fn play(&mut self) {
        self.playing = true;
    }

    pub fn pause(&mut self) {
        self.playing = false;
    }

    pub fn toggle_play(&mut self) {
        self.playing = !self.playing;
    }

    /// Sets the speed (× real time) within [`SPEED_RANGE`].
    pub fn set_speed(&mut self, speed: f64) -> Result<(), PlaybackError> {
        if !speed.is_finite() || speed < SPEED_RANGE.0 || speed > SPEED_RANGE.1 {
            return Err(PlaybackError::BadSpeed(speed));
        }
        self.speed = speed;
        Ok(())
    }

    /// Moves `delta` whole frames (negative = back), clamped to the first/last frame, and
    /// pauses: stepping is for inspecting single frames. Returns the new frame.
    pub fn step(&mut self, delta: f64) -> Result<usize, PlaybackError> {
        if !delta.is_finite() || delta.fract() != 0.0 {
            return Err(PlaybackError::BadStep(delta));
        }
        self.playing = false;
        let target = self.frame() as f64 + delta;
        self.set_frame(target);
        Ok(self.frame())
    }

    /// Shows frame `frame` (rounded to the nearest whole frame, clamped to the timeline);
    /// keeps playing if it was. Returns the new frame.
    pub fn seek(&mut self, frame: f64) -> Result<usize, PlaybackError> {
        if !frame.is_finite() {
            return Err(PlaybackError::BadFrame(frame));
        }
        self.set_frame(frame.round());
        Ok(self.frame())
    }

    /// Moves by `seconds` of scene time (e.g. ±1 s from the keyboard), clamped to the
    /// timeline; keeps playing if it was. Returns the new frame.
    pub fn seek_by_seconds(&mut self, seconds: f64) -> Result<usize, PlaybackError> {
        if !seconds.is_finite() {
            return Err(PlaybackError::BadSeconds(seconds));
        }
        let target = self.frame() as f64 + (seconds * self.fps).round();
        self.set_frame(target);
        Ok(self.frame())
    }

    /// Plays frames `start..=end` in a loop (clamped to the timeline; a link's `t=a-b`), or the
    /// whole timeline with `None`. Seeking and stepping may still leave the range; playing
    /// from outside it jumps to its start.
    pub fn set_loop(&mut self, range: Option<(usize, usize)>) {
        let last = self.frames.saturating_sub(1);
        self.loop_range = range.map(|(a, b)| (a.min(last), b.min(last))).filter(|(a, b)| a < b);
    }

    /// The looped frames, if any.
    pub fn loop_range(&self) -> Option<(usize, usize)> {
        self.loop_range
    }

    /// Advances by `dt_s` seconds of wall-clock time (at most [`MAX_ADVANCE_S`]; negative or
    /// non-finite counts as 0) when playing, wrapping past the last frame (or the loop's end)
    /// to the first (or the loop's start). Returns whether the shown frame changed.
    pub fn advance(&mut self, dt_s: f64) -> bool {
        if !self.playing || self.frames < 2 {
            return false;
        }
        let dt = if dt_s.is_finite() { dt_s.clamp(0.0, MAX_ADVANCE_S) } else { 0.0 };
        let before = self.frame();
        let (start, end) = self.loop_range.map_or((0.0, self.frames as f64), |(a, b)| (a as f64, (b + 1) as f64));
        if self.position < start || self.position >= end {
            self.position = start;
        } else {
            self.position = start + (self.position - start + dt * self.fps * self.speed).rem_euclid(end - start);
        }
        self.frame() != before
    }

    fn set_frame(&mut self, frame: f64) {
        let last = self.frames.saturating_sub(1) as f64;
        self.position = frame.clamp(0.0, last);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    #[test]
    fn plays_at_the_scene_rate_times_speed() {
        let mut p = Playback::new(100, 30.0);
        assert!(!p.advance(0.1), "paused timelines do not move");
        p.play();
        assert!(p.advance(0.1));
        assert_eq!(p.frame(), 3);
        p.set_speed(2.0).unwrap();
        p.advance(0.1);
        assert_eq!(p.frame(), 9);
        assert!((p.time_s() - 0.3).abs() < 1e-9);
        // Slow speeds accumulate fractions of a frame.
        p.set_speed(0.1).unwrap();
        p.seek(9.0).unwrap();
        let changes = (0..21).filter(|_| p.advance(1.0 / 60.0)).count();
        assert_eq!(p.frame(), 10);
        assert_eq!(changes, 1);
    }

    #[test]
    fn playback_wraps_past_the_last_frame() {
        let mut p = Playback::new(10, 10.0);
        p.seek(8.0).unwrap();
        p.play();
        p.advance(0.25); // 2.5 frames: 8 → 10.5 → wraps to 0.5
        assert_eq!(p.frame(), 0);
        assert!(p.is_playing());
    }

    #[test]
    fn a_loop_range_wraps_inside_itself() {
        let mut p = Playback::new(100, 10.0);
        p.set_loop(Some((20, 29)));
        p.play();
        p.advance(0.0);
        assert_eq!(p.frame(), 20, "playing from outside the range starts at its start");
        for _ in 0..40 {
            p.advance(0.1);
            assert!((20..=29).contains(&p.frame()), "{}", p.frame());
        }
        p.set_loop(Some((50, 500)));
        assert_eq!(p.loop_range(), Some((50, 99)));
        p.set_loop(Some((5, 5)));
        assert_eq!(p.loop_range(), None, "an empty range plays everything");
    }

    #[test]
    fn long_pauses_do_not_jump_far() {
        let mut p = Playback::new(1000, 30.0);
        p.play();
        p.advance(60.0);
        assert_eq!(p.frame(), (MAX_ADVANCE_S * 30.0) as usize);
        assert!(!p.advance(-1.0));
        assert!(!p.advance(f64::NAN));
    }

    #[test]
    fn step_clamps_and_pauses() {
        let mut p = Playback::new(5, 30.0);
        p.play();
        assert_eq!(p.step(1.0), Ok(1));
        assert!(!p.is_playing());
        assert_eq!(p.step(-3.0), Ok(0));
        assert_eq!(p.step(100.0), Ok(4));
        assert_eq!(p.step(0.5), Err(PlaybackError::BadStep(0.5)));
        assert!(p.step(f64::INFINITY).is_err());
        assert_eq!(p.frame(), 4);
    }

    #[test]
    fn seek_rounds_clamps_and_refuses_nan() {
        let mut p = Playback::new(50, 25.0);
        p.play();
        assert_eq!(p.seek(12.6), Ok(13));
        assert!(p.is_playing(), "scrubbing keeps playing");
        assert_eq!(p.seek(-4.0), Ok(0));
        assert_eq!(p.seek(1e9), Ok(49));
        assert!(matches!(p.seek(f64::NAN), Err(PlaybackError::BadFrame(_))));
        assert_eq!(p.frame(), 49);
        assert_eq!(p.seek_by_seconds(-1.0), Ok(24));
        assert_eq!(p.seek_by_seconds(1.0), Ok(49));
        assert!(p.seek_by_seconds(f64::NAN).is_err());
    }

    #[test]
    fn speed_is_bounded() {
        let mut p = Playback::new(10, 30.0);
        for bad in [0.0, -1.0, 0.01, 100.0, f64::NAN, f64::INFINITY] {
            assert!(p.set_speed(bad).is_err(), "{bad}");
        }
        assert_eq!(p.speed(), 1.0);
        p.set_speed(0.25).unwrap();
        assert_eq!(p.speed(), 0.25);
        assert!(PlaybackError::BadSpeed(-1.0).to_string().contains("got -1"));
    }

    #[test]
    fn empty_and_single_frame_timelines_are_safe() {
        let mut p = Playback::new(0, 30.0);
        p.play();
        assert!(!p.advance(0.1));
        assert_eq!(p.seek(5.0), Ok(0));
        assert_eq!(p.step(1.0), Ok(0));
        assert_eq!(p.time_s(), 0.0);
        let mut one = Playback::new(1, 30.0);
        one.play();
        assert!(!one.advance(0.2));
        assert_eq!(one.frame(), 0);
        // A bad rate never divides by zero.
        assert_eq!(Playback::new(3, 0.0).fps(), 30.0);
        assert_eq!(Playback::new(3, f64::NAN).fps(), 30.0);
    }
}
