//! Where a reconstruction's time goes, per stage, measured with a clock the caller passes in.
//!
//! The engine never reads a clock (it runs in the browser's worker, where the page owns
//! time): a caller that wants timings hands
//! [`ReconstructionJob::step_timed`](crate::ReconstructionJob::step_timed) a [`Clock`] — `Instant` natively, the worker's
//! `performance.now()` in the browser — and reads the [`StageTimings`] the job summed. The
//! stages outside the engine (import, align, scene, export) are timed by their callers into
//! the same table, so the CLI, the worker and the bench page print one layout.

use std::fmt;

use serde::{Deserialize, Serialize};

/// A stage of the app's whole job, in pipeline order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TimedStage {
    /// Reading the session's files into a session (callers).
    Import,
    /// Resampling every stream onto the reconstruction timeline (callers).
    Align,
    /// Checking and registering the observers' worlds against the wearer (callers:
    /// `egoexo-register`, with its coarse body).
    Register,
    /// The wearer's ego features of a window (`inputs::ego_window`).
    EgoFeatures,
    /// EgoNet's coarse pose of a window.
    EgoNet,
    /// Regions, canonical rays, ray offsets and gate features of a window
    /// (`inputs::exo_window`).
    ExoFeatures,
    /// The gate network.
    Gate,
    /// The fusion network (with its gated exo input).
    Fusion,
    /// Cross-fading windows into frames, world frame, root by FK, floor contact.
    Decode,
    /// Building what the viewer draws (callers).
    Scene,
    /// Writing an export file (callers).
    Export,
}

impl TimedStage {
    /// Every stage, in pipeline order.
    pub const ALL: [TimedStage; 11] = [
        TimedStage::Import,
        TimedStage::Align,
        TimedStage::Register,
        TimedStage::EgoFeatures,
        TimedStage::EgoNet,
        TimedStage::ExoFeatures,
        TimedStage::Gate,
        TimedStage::Fusion,
        TimedStage::Decode,
        TimedStage::Scene,
        TimedStage::Export,
    ];

    /// The name used in tables (kebab-case, as serialised).
    pub fn name(self) -> &'static str {
        match self {
            TimedStage::Import => "import",
            TimedStage::Align => "align",
            TimedStage::Register => "register",
            TimedStage::EgoFeatures => "ego-features",
            TimedStage::EgoNet => "egonet",
            TimedStage::ExoFeatures => "exo-features",
            TimedStage::Gate => "gate",
            TimedStage::Fusion => "fusion",
            TimedStage::Decode => "decode",
            TimedStage::Scene => "scene",
            TimedStage::Export => "export",
        }
    }

    /// Whether the stage runs a network.
    pub fn is_network(self) -> bool {
        matches!(self, TimedStage::EgoNet | TimedStage::Gate | TimedStage::Fusion)
    }
}

impl fmt::Display for TimedStage {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A monotonic clock in milliseconds (any origin), supplied by the caller.
pub trait Clock {
    fn now_ms(&mut self) -> f64;
}

impl<F: FnMut() -> f64> Clock for F {
    fn now_ms(&mut self) -> f64 {
        self()
    }
}

/// Time summed per stage: milliseconds and how many times the stage ran.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StageTimings {
    /// `(stage, milliseconds, calls)`, in pipeline order, stages that ran only.
    pub stages: Vec<StageTime>,
}

/// One stage's summed time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StageTime {
    pub stage: TimedStage,
    /// Milliseconds, summed over its calls.
    pub ms: f64,
    /// How many times it ran (windows, for the engine's stages).
    pub calls: u32,
}

impl StageTimings {
    /// Adds `ms` to `stage` (one call).
    pub fn add(&mut self, stage: TimedStage, ms: f64) {
        self.add_time(stage, ms, 1);
    }

    /// Adds `ms` and `calls` to `stage`.
    pub fn add_time(&mut self, stage: TimedStage, ms: f64, calls: u32) {
        match self.stages.binary_search_by(|s| s.stage.cmp(&stage)) {
            Ok(i) => {
                self.stages[i].ms += ms;
                self.stages[i].calls += calls;
            }
            Err(i) => self.stages.insert(i, StageTime { stage, ms, calls }),
        }
    }

    /// Adds every stage of `other`.
    pub fn merge(&mut self, other: &StageTimings) {
        for s in &other.stages {
            self.add_time(s.stage, s.ms, s.calls);
        }
    }

    /// Milliseconds of `stage` (0 when it did not run).
    pub fn ms(&self, stage: TimedStage) -> f64 {
        self.stages.iter().find(|s| s.stage == stage).map_or(0.0, |s| s.ms)
    }

    /// Milliseconds over every stage.
    pub fn total_ms(&self) -> f64 {
        self.stages.iter().map(|s| s.ms).sum()
    }

    /// Per stage, the median over `runs` of its milliseconds (a stage missing from a run
    /// counts 0 there); calls from the first run that has the stage.
    pub fn median(runs: &[StageTimings]) -> StageTimings {
        let mut stages = Vec::new();
        for stage in TimedStage::ALL {
            let Some(calls) = runs.iter().find_map(|r| r.stages.iter().find(|s| s.stage == stage).map(|s| s.calls))
            else {
                continue;
            };
            let ms: Vec<f64> = runs.iter().map(|r| r.ms(stage)).collect();
            stages.push(StageTime { stage, ms: median(&ms), calls });
        }
        StageTimings { stages }
    }

    /// A plain-text table: stage, ms, calls, ms per call, share of the total.
    pub fn table(&self) -> String {
        let total = self.total_ms();
        let mut out = format!("{:<14} {:>10} {:>7} {:>10} {:>7}\n", "stage", "ms", "calls", "ms/call", "share");
        for s in &self.stages {
            out += &format!(
                "{:<14} {:>10.2} {:>7} {:>10.3} {:>6.1}%\n",
                s.stage.name(),
                s.ms,
                s.calls,
                s.ms / f64::from(s.calls.max(1)),
                if total > 0.0 { 100.0 * s.ms / total } else { 0.0 }
            );
        }
        out += &format!("{:<14} {:>10.2}\n", "total", total);
        out
    }
}

/// The median of `xs` (0 for none).
pub fn median(xs: &[f64]) -> f64 {
    let mut s: Vec<f64> = xs.iter().copied().filter(|x| x.is_finite()).collect();
    if s.is_empty() {
        return 0.0;
    }
    s.sort_by(f64::total_cmp);
    let m = s.len() / 2;
    if s.len() % 2 == 1 { s[m] } else { 0.5 * (s[m - 1] + s[m]) }
}

/// Times stages into a [`StageTimings`] with an optional clock; without one it only runs
/// them.
pub struct StageTimer<'a> {
    clock: Option<&'a mut dyn Clock>,
    /// What has been timed so far.
    pub timings: StageTimings,
}

impl<'a> StageTimer<'a> {
    /// A timer reading `clock`.
    pub fn new(clock: &'a mut dyn Clock) -> Self {
        StageTimer { clock: Some(clock), timings: StageTimings::default() }
    }

    /// A timer that times nothing.
    pub fn off() -> StageTimer<'static> {
        StageTimer { clock: None, timings: StageTimings::default() }
    }

    /// Runs `f`, adding its time to `stage` when the timer has a clock.
    pub fn time<T>(&mut self, stage: TimedStage, f: impl FnOnce() -> T) -> T {
        match self.clock.as_deref_mut() {
            None => f(),
            Some(clock) => {
                let start = clock.now_ms();
                let out = f();
                let ms = clock.now_ms() - start;
                self.timings.add(stage, ms.max(0.0));
                out
            }
        }
    }
}

impl fmt::Debug for StageTimer<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("StageTimer").field("clocked", &self.clock.is_some()).field("timings", &self.timings).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_timer_sums_each_stage_with_the_clock_it_is_given() {
        let mut t = 0.0;
        let mut clock = move || {
            t += 2.5;
            t
        };
        let mut timer = StageTimer::new(&mut clock);
        assert_eq!(timer.time(TimedStage::Fusion, || 7), 7);
        timer.time(TimedStage::EgoNet, || ());
        timer.time(TimedStage::Fusion, || ());
        let fusion = timer.timings.stages.iter().find(|s| s.stage == TimedStage::Fusion).unwrap();
        assert_eq!((fusion.ms, fusion.calls), (5.0, 2));
        // Pipeline order, whatever order they ran in.
        let order: Vec<_> = timer.timings.stages.iter().map(|s| s.stage).collect();
        assert_eq!(order, [TimedStage::EgoNet, TimedStage::Fusion]);
        assert_eq!(timer.timings.total_ms(), 7.5);
    }

    #[test]
    fn a_timer_without_a_clock_times_nothing() {
        let mut timer = StageTimer::off();
        assert_eq!(timer.time(TimedStage::Gate, || 3), 3);
        assert!(timer.timings.stages.is_empty());
    }

    #[test]
    fn medians_are_per_stage_and_count_a_missing_stage_as_zero() {
        let run = |fusion: f64, gate: Option<f64>| {
            let mut t = StageTimings::default();
            t.add(TimedStage::Fusion, fusion);
            if let Some(g) = gate {
                t.add(TimedStage::Gate, g);
            }
            t
        };
        let m = StageTimings::median(&[run(3.0, Some(1.0)), run(1.0, None), run(2.0, Some(5.0))]);
        assert_eq!(m.ms(TimedStage::Fusion), 2.0);
        assert_eq!(m.ms(TimedStage::Gate), 1.0);
        assert!(m.table().contains("fusion"));
    }
}
