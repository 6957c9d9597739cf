//! The effect library's tests.

use super::*;
use crate::config::{ConfigSource, Document, Embedded};
use crate::gap::model::GapModel;
use crate::gap::{bench, generate, resim};
use crate::physics::experiment::Experiment;

/// Every effect of the library, applied at its typical size, changes the noise-free
/// prediction of at least one of its signature channels by more than a hundredth of the
/// channel's measurement noise, on the benchmark's manoeuvre re-anchored every 5 s: no
/// effect is invisible in the channels its signature test looks at.
#[test]
fn every_effect_shows_in_its_signature_channels() {
    let text = Embedded.read(bench::MODEL).expect("model");
    let model = GapModel::from_text(&Embedded.describe(bench::MODEL), &text, ".".into())
        .expect("model parses");
    let sched_text = Embedded.read(bench::SCHEDULE).expect("schedule");
    let schedule = bench::training(
        &Experiment::from_document(&Document::new(
            Embedded.describe(bench::SCHEDULE),
            &sched_text,
        ))
        .expect("schedule parses"),
    );
    let info = generate::setup(&model, &schedule, bench::CAMERA_STD_M);
    let dir = std::path::Path::new(".");
    let base = model.configs(&info, dir).expect("configs");
    let m = generate::generate(
        &base,
        &schedule,
        &info.world,
        &info.sensors,
        bench::CAMERA_STD_M,
        11,
    )
    .expect("generates");
    let mut base = base;
    base.shooting = Shooting::DEFAULT;
    let run0 = resim::simulate(&base, &m, None).expect("runs");
    for effect in LIBRARY.iter().filter(|e| e.kind == Kind::Mean) {
        if effect.name == "sonar_incidence_dropout" {
            continue; // needs a wall in view: the sonar fixtures test it
        }
        let mut c = base.clone();
        apply(effect, effect.scales, &mut c);
        assert_ne!(c, base, "{} changed no configuration", effect.name);
        let run1 = resim::simulate(&c, &m, None).expect("runs");
        let shows = m
            .channels
            .iter()
            .filter(|ch| effect.channels.contains(&ch.name.as_str()))
            .any(|ch| {
                let (Some(a), Some(b)) = (
                    resim::predict(&base, &run0, ch, 0.0),
                    resim::predict(&c, &run1, ch, 0.0),
                ) else {
                    return false;
                };
                let noise = resim::measurement_std(&base, &m, &run0, ch);
                a.iter()
                    .zip(&b)
                    .zip(&noise)
                    .any(|((x, y), s)| (x - y).abs() > 0.01 * s)
            });
        assert!(
            shows,
            "{} left its signature channels unchanged",
            effect.name
        );
    }
}

/// An effect is one entry of [`LIBRARY`]: no other source file of the crate names it
/// outside its tests, the effect library's doc has its row, and the independent model
/// knows every effect the benchmarks hide under the name its entry gives.
#[test]
fn every_effect_lives_in_its_entry_its_doc_row_and_the_independent_model() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut sources = Vec::new();
    let mut stack = vec![root.join("src")];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("src is readable") {
            let path = entry.expect("entry").path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs")
                && !path.ends_with("gap/effects/library.rs")
                && path.file_name().is_none_or(|n| n != "tests.rs")
            {
                let text = std::fs::read_to_string(&path).expect("source is UTF-8");
                // Unit tests (a `tests.rs` file or what follows `#[cfg(test)]`) and comments
                // may name effects; the code may not.
                let code: String = text
                    .split("#[cfg(test)]")
                    .next()
                    .unwrap_or("")
                    .lines()
                    .filter(|l| !l.trim_start().starts_with("//"))
                    .collect::<Vec<_>>()
                    .join("\n");
                sources.push((path, code));
            }
        }
    }
    let doc = std::fs::read_to_string(root.join("docs/gap/effects.md")).expect("doc");
    let independent =
        std::fs::read_to_string(root.join("pty-tests/independent/mako_independent.py"))
            .expect("independent model");
    for e in &LIBRARY {
        let quoted = format!("\"{}\"", e.name);
        for (path, code) in &sources {
            assert!(
                !code.contains(&quoted),
                "{} names the effect `{}`: iterate over the library instead",
                path.display(),
                e.name
            );
        }
        assert!(
            doc.contains(&format!("| `{}` |", e.name)),
            "docs/gap/effects.md has no row for `{}`",
            e.name
        );
        if let Some(h) = e.hidden {
            assert!(
                independent.contains(&format!("\"{}\":", h.independent)),
                "the independent model has no effect `{}` (the benchmarks hide `{}` as it)",
                h.independent,
                e.name
            );
        }
    }
}

/// Bounds: each effect has one per parameter, around the no-effect value 0, and
/// `inside_bounds` rejects a value on a bound.
#[test]
fn bounds_hold_no_effect_and_reject_their_edges() {
    for e in &LIBRARY {
        assert_eq!(e.bounds.len(), e.parameters.len(), "{}", e.name);
        assert_eq!(e.scales.len(), e.parameters.len(), "{}", e.name);
        for (lo, hi) in e.bounds {
            assert!(*lo <= 0.0 && 0.0 <= *hi && lo < hi, "{}", e.name);
        }
        let mut at_edge: Vec<f64> = e.bounds.iter().map(|(_, hi)| *hi).collect();
        assert!(!inside_bounds(e, &at_edge), "{}", e.name);
        clamp_to_bounds(e, &mut at_edge);
        let mid: Vec<f64> = e.bounds.iter().map(|(lo, hi)| 0.5 * (lo + hi)).collect();
        assert!(inside_bounds(e, &mid), "{}", e.name);
    }
}
