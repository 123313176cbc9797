//! The passes of a fit in order (simultaneous, the stages, joint), with the interrupt, the
//! hand-out after every pass and the resume from an interrupted run.

use std::time::Instant;

use itaipu_dynamics::event::Event;
use itaipu_dynamics::unit::Unit;

use crate::bounds::clamp_into;
use crate::problem::FreeParam;
use crate::spec::{CalibSpec, StageSpec, Strategy, STAGES};

use super::*;

/// Calibrates `unit` against `events` following `spec` (stages in `opts.stages`).
pub fn fit(
    unit: &Unit,
    spec: &CalibSpec,
    events: &[Event],
    held_out: &[Event],
    opts: &FitOptions,
    progress: &dyn Progress,
) -> Result<FitResult, FitError> {
    fit_with(
        unit,
        spec,
        events,
        held_out,
        opts,
        progress,
        &FitControl::default(),
    )
}

/// [`fit`] with an interrupt flag, a hook called after every finished pass, and a resume from
/// the passes of an interrupted run ([`FitControl`]). On resume the returned report and
/// outputs hold only the passes run now.
pub fn fit_with(
    unit: &Unit,
    spec: &CalibSpec,
    events: &[Event],
    held_out: &[Event],
    opts: &FitOptions,
    progress: &dyn Progress,
    control: &FitControl<'_>,
) -> Result<FitResult, FitError> {
    let t0 = Instant::now();
    if events.is_empty() {
        return Err(FitError::Setup("no event to fit".into()));
    }
    opts.check()?;
    // `channels = "recorded"` becomes the weights of the field channels every event records,
    // fitted and held out (one place, so every front end fits the same).
    let resolved;
    let spec = if spec.compares_recorded() {
        let fitted: Vec<&Event> = events.iter().collect();
        let held: Vec<&Event> = held_out.iter().collect();
        resolved = spec.resolve_recorded(&fitted, &held);
        &resolved
    } else {
        spec
    };
    for s in &opts.stages {
        if !STAGES.contains(&s.as_str()) {
            return Err(FitError::Setup(format!(
                "unknown stage '{s}' (gen, avr, pss, tg)"
            )));
        }
        if spec.stage(s).is_none() {
            return Err(FitError::Setup(format!(
                "stage '{s}' is not in the calibration spec"
            )));
        }
    }
    check_spec(unit, spec, &opts.stages)?;
    let joint_runs = opts.polish && opts.stages.len() > 1;
    check_events(spec, None, &opts.stages, joint_runs, events, held_out)?;
    // With playback modes every fitness row reports every mode of the fit.
    let rows = spec.compares(&opts.stages, joint_runs);
    let first = opts
        .stages
        .first()
        .and_then(|s| spec.stage(s))
        .and_then(|st| st.compare());
    let labels = pass_labels(opts);
    let skip = match &control.resume {
        None => 0,
        Some(r) => {
            if r.finished.len() > labels.len() || r.finished[..] != labels[..r.finished.len()] {
                return Err(FitError::Setup(format!(
                    "cannot resume: the finished stages ({}) are not the first passes of this fit ({}); give the same stages, strategy and options as the interrupted run",
                    r.finished.join(", "),
                    labels.join(", ")
                )));
            }
            r.finished.len()
        }
    };
    let mut master = unit.clone();
    let mut start_fitness = vec![];
    for e in events {
        start_fitness.push(
            row_fitness(&master, e, false, &rows, first.as_ref())
                .map_err(FitError::Start)?
                .0,
        );
    }
    for e in held_out {
        if let Ok((f, _)) = row_fitness(&master, e, true, &rows, first.as_ref()) {
            start_fitness.push(f);
        }
    }
    if let Some(r) = &control.resume {
        if skip > 0 {
            master = r.master.clone();
        }
    }
    let mut passes = Passes {
        rows: &rows,
        events,
        held_out,
        progress,
        control,
        skip,
        pass: 0,
        finished: labels[..skip].to_vec(),
        reports: vec![],
        outputs: vec![],
        watch: super::worsening::Watch::new(events),
    };

    if opts.strategy == Strategy::SimultaneousFirst && passes.next()? {
        // All listed stages' parameters at once on the full unit, objective P+Q.
        let mut full = master.clone();
        for s in &opts.stages {
            apply_stage_edits(&mut full, spec.stage(s).expect("checked"))?;
        }
        let all = combined_stage("all", spec, &opts.stages);
        let free = free_params(&full, &all, unit, spec.prior)?;
        let (rep, out, best) =
            passes.run(opts, "all", "simultaneous", full.clone(), &free, &all, &[])?;
        // The full unit (with every stage's replacements) carries on with the joint result.
        master = full;
        for (f, v) in free.iter().zip(&best) {
            master.set(f.r, *v);
        }
        apply_ties(&mut master, &all)?;
        passes.hand_out(rep, out, &master, &all)?;
    }

    for s in &opts.stages {
        if !passes.next()? {
            continue;
        }
        let st = spec.stage(s).expect("checked");
        apply_stage_edits(&mut master, st)?;
        let stage_unit = master
            .without(spec.removed_blocks(s))
            .map_err(|e| stage_err(s, e.to_string()))?;
        let free = free_params(&stage_unit, st, unit, spec.prior)?;
        let (rep, out, best) = passes.run(opts, s, s, stage_unit, &free, st, &[])?;
        for (f, v) in free.iter().zip(&best) {
            let r = master
                .param(&f.path)
                .map_err(|e| stage_err(s, e.to_string()))?;
            master.set(r, *v);
        }
        apply_ties(&mut master, st)?;
        passes.hand_out(rep, out, &master, st)?;
    }

    if opts.polish && opts.stages.len() > 1 && passes.next()? {
        // Joint refinement of everything the stages freed, on the full unit.
        let mut joint = combined_stage("joint", spec, &opts.stages);
        joint.lowpass_hz = None;
        let full = master.clone();
        let free = free_params(&full, &joint, unit, spec.prior)?;
        // Start from the current values, not the spec's starting values.
        let free: Vec<FreeParam> = free
            .into_iter()
            .map(|f| FreeParam {
                start: clamp_into(full.get(f.r), f.lo, f.hi),
                ..f
            })
            .collect();
        // A second start at the datasheet values (the prior's centre where there is one), in
        // case the staged result lies in another, worse basin.
        let datasheet: Vec<f64> = free
            .iter()
            .map(|f| clamp_into(f.prior.map_or(f.start, |p| p.center), f.lo, f.hi))
            .collect();
        let (rep, out, best) = passes.run(
            &opts.joint_pass(),
            "joint",
            "joint",
            full,
            &free,
            &joint,
            &[datasheet],
        )?;
        for (f, v) in free.iter().zip(&best) {
            master.set(f.r, *v);
        }
        apply_ties(&mut master, &joint)?;
        passes.hand_out(rep, out, &master, &joint)?;
    }
    let Passes {
        reports, outputs, ..
    } = passes;

    let report = FitReport {
        unit: unit.name.clone(),
        events: events.iter().map(|e| e.name.clone()).collect(),
        held_out: held_out.iter().map(|e| e.name.clone()).collect(),
        strategy: opts.strategy.to_string(),
        seed: opts.seed,
        threads: rayon::current_num_threads(),
        start_fitness,
        stages: reports,
        wall_s: t0.elapsed().as_secs_f64(),
    };
    Ok(FitResult {
        report,
        unit: master,
        stages: outputs,
    })
}

/// The passes of one fit as they run: what is shared by every pass's call and what the passes
/// so far have given.
struct Passes<'a> {
    /// The fit's comparisons, reported in every fitness row ([`row_fitness`]).
    rows: &'a [crate::spec::Compare],
    events: &'a [Event],
    held_out: &'a [Event],
    progress: &'a dyn Progress,
    control: &'a FitControl<'a>,
    /// Passes finished by the resumed run (skipped now).
    skip: usize,
    /// Index of the next pass.
    pass: usize,
    finished: Vec<String>,
    reports: Vec<StageReport>,
    outputs: Vec<StageOutput>,
    /// What the passes so far compared, for the channels a pass makes far worse.
    watch: super::worsening::Watch,
}

impl Passes<'_> {
    fn interrupted(&self) -> FitError {
        FitError::Interrupted {
            finished: self.finished.clone(),
        }
    }

    /// Before each pass: whether to run it (not when resumed past it);
    /// [`FitError::Interrupted`] when the fit is cancelled.
    fn next(&mut self) -> Result<bool, FitError> {
        if self.control.cancelled() {
            return Err(self.interrupted());
        }
        self.pass += 1;
        Ok(self.pass > self.skip)
    }

    /// Runs one pass ([`run_stage`]) with its options (the fit's, or the joint pass's,
    /// [`FitOptions::joint_pass`]); the pass is dropped when the fit was interrupted during it.
    #[allow(clippy::too_many_arguments)]
    fn run(
        &self,
        opts: &FitOptions,
        name: &str,
        label: &str,
        unit: Unit,
        free: &[FreeParam],
        spec: &StageSpec,
        also_from: &[Vec<f64>],
    ) -> Result<(StageReport, StageOutput, Vec<f64>), FitError> {
        let res = run_stage(
            name,
            label,
            unit,
            free.to_vec(),
            spec,
            self.events,
            self.held_out,
            opts,
            self.progress,
            true,
            also_from,
            self.control.cancel.clone(),
            self.rows,
        );
        if self.control.cancelled() {
            return Err(self.interrupted());
        }
        res
    }

    /// After a pass (with stage spec `spec`): the channels earlier passes compared that it made
    /// far worse go into its report and onto the terminal ([`super::worsening`]); then it is
    /// handed out ([`FitControl::on_stage`], with the full unit `master` it leaves) and its
    /// report and outputs kept.
    fn hand_out(
        &mut self,
        mut rep: StageReport,
        out: StageOutput,
        master: &Unit,
        spec: &StageSpec,
    ) -> Result<(), FitError> {
        let before = self.reports.last().map(|r| r.fitness.as_slice());
        rep.worsened = self
            .watch
            .after_pass(&rep.stage, spec, before, &rep.fitness);
        for w in &rep.worsened {
            self.progress.message(&format!("warning: {}", w.sentence()));
        }
        if let Some(f) = self.control.on_stage {
            f(&rep, &out, master)?;
        }
        self.finished.push(rep.stage.clone());
        self.reports.push(rep);
        self.outputs.push(out);
        Ok(())
    }
}
