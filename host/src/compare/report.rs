//! The comparison as Table II (Markdown and CSV) and Figure 3, and the
//! sentences saying where a baseline beats cascade correlation.

use std::path::{Path, PathBuf};

use super::{CompareError, Comparison, Entry, REFERENCE};
use crate::plot::compare::{draw_comparison, LearnerBars};
use crate::units;

/// A metric column: header, CSV name, how to read it from an entry and how
/// to print it (smaller is better in every column).
struct Column {
    header: &'static str,
    csv: &'static str,
    get: fn(&Entry) -> f64,
    shown: Shown,
}

/// How a column's numbers are printed: every number keeps at least two
/// significant digits ([`crate::units`]), so the best learners' errors do
/// not print as 0.000.
#[derive(Clone, Copy)]
enum Shown {
    /// A plain number with at least this many decimals.
    Number(usize),
    /// A number with at least this many decimals, or "n/a" (NaN) for a
    /// learner the column does not apply to.
    Optional(usize),
    /// A count.
    Count,
    /// A length kept in millimetres, printed in the unit that fits it.
    LengthMm,
    /// An angle in degrees.
    Degrees,
}

impl Shown {
    fn text(self, v: f64) -> String {
        match self {
            Shown::Number(d) => units::number(v, d),
            Shown::Optional(_) if v.is_nan() => "n/a".into(),
            Shown::Optional(d) => units::number(v, d),
            Shown::Count => format!("{v:.0}"),
            Shown::LengthMm => units::length_mm(v),
            Shown::Degrees => units::degrees(v),
        }
    }

    /// `a` is strictly below `b` at the precision the table shows.
    fn below(self, a: f64, b: f64) -> bool {
        match self {
            Shown::Number(d) | Shown::Optional(d) => units::shown_below(a, b, d),
            Shown::Count => units::shown_below(a.round(), b.round(), 0),
            // Lengths and angles keep two significant digits of the larger.
            Shown::LengthMm => units::shown_below(a, b, 0),
            Shown::Degrees => units::shown_below(a, b, 3),
        }
    }
}

fn columns() -> Vec<Column> {
    vec![
        Column {
            header: "RMSE×100 train",
            csv: "rmse_norm100_train",
            get: |e| e.train.tension_rmse_norm100,
            shown: Shown::Number(3),
        },
        Column {
            header: "RMSE×100 test",
            csv: "rmse_norm100_test",
            get: |e| e.test.tension_rmse_norm100,
            shown: Shown::Number(3),
        },
        Column {
            header: "RMSE N train",
            csv: "rmse_newton_train",
            get: |e| e.train.tension_rmse_newton,
            shown: Shown::Number(4),
        },
        Column {
            header: "RMSE N test",
            csv: "rmse_newton_test",
            get: |e| e.test.tension_rmse_newton,
            shown: Shown::Number(4),
        },
        Column {
            header: "tip mean (train)",
            csv: "tip_mean_mm_train",
            get: |e| e.train.position_mm.mean,
            shown: Shown::LengthMm,
        },
        Column {
            header: "tip mean",
            csv: "tip_mean_mm_test",
            get: |e| e.test.position_mm.mean,
            shown: Shown::LengthMm,
        },
        Column {
            header: "tip p95",
            csv: "tip_p95_mm_test",
            get: |e| e.test.position_mm.p95,
            shown: Shown::LengthMm,
        },
        Column {
            header: "tip max",
            csv: "tip_max_mm_test",
            get: |e| e.test.position_mm.max,
            shown: Shown::LengthMm,
        },
        Column {
            header: "angle mean",
            csv: "angle_mean_deg_test",
            get: |e| e.test.orientation_deg.mean,
            shown: Shown::Degrees,
        },
        Column {
            header: "solve failures",
            csv: "failed_solves_test",
            get: |e| e.test.failed_solves as f64,
            shown: Shown::Count,
        },
        Column {
            header: "train s",
            csv: "train_seconds",
            get: |e| e.train_seconds,
            shown: Shown::Number(2),
        },
        Column {
            header: "µs/query",
            csv: "infer_us_per_query",
            get: |e| e.infer_us,
            shown: Shown::Number(2),
        },
        Column {
            header: "µs/row batched",
            csv: "infer_us_per_row_batched",
            get: |e| e.infer_batched_us,
            shown: Shown::Number(2),
        },
        Column {
            header: "µs/query, fast path",
            csv: "infer_us_per_query_fast",
            get: |e| e.infer_fast_us.unwrap_or(f64::NAN),
            shown: Shown::Optional(2),
        },
        Column {
            header: "parameters",
            csv: "parameters",
            get: |e| e.parameters as f64,
            shown: Shown::Count,
        },
    ]
}

impl Comparison {
    /// The reference learner's entry (cascade correlation), if it ran.
    pub fn reference(&self) -> Option<&Entry> {
        self.entries.iter().find(|e| e.name == REFERENCE)
    }

    /// For each baseline that is strictly better than cascade correlation on
    /// some column (at the precision the table shows), one sentence listing
    /// those columns with both values.
    pub fn beats(&self) -> Vec<String> {
        let Some(r) = self.reference() else {
            return Vec::new();
        };
        let cols = columns();
        let mut v = Vec::new();
        for e in self.entries.iter().filter(|e| e.name != REFERENCE) {
            let wins: Vec<String> = cols
                .iter()
                .filter_map(|c| {
                    let (ev, rv) = ((c.get)(e), (c.get)(r));
                    c.shown.below(ev, rv).then(|| {
                        format!(
                            "{} ({} vs {})",
                            c.header,
                            c.shown.text(ev),
                            c.shown.text(rv)
                        )
                    })
                })
                .collect();
            if !wins.is_empty() {
                v.push(format!(
                    "{} beats {REFERENCE} on {}",
                    e.name,
                    wins.join(", ")
                ));
            }
        }
        v
    }

    /// Table II as Markdown, with the chosen hyper-parameters, the best value
    /// of each column in bold, and every metric where a baseline beats
    /// cascade correlation listed below.
    pub fn to_markdown(&self) -> String {
        let cols = columns();
        let (nf, nv, nt) = self.sizes;
        let o = &self.options;
        let mut s = format!(
            "# Learner comparison ({})\n\n\
             Same split and normalisation for every learner: {nf} training rows, {nv} validation rows \
             (hyper-parameters chosen on these only), {nt} test rows; seed {}. \
             Tension RMSE over all tendons (normalised units ×100 and newtons). Task-space error: \
             predicted tensions → the firmware's command stage (co-contraction shift, then the clip to \
             [τ_min, τ_max]: what the MCU commands) → Cosserat statics → tip, against the true tip; \
             test split in full, train split on a seeded subsample of {} rows. \
             Inference time, the same harness for every learner (its `predict`, one thread): \
             single-row queries (a 1-row matrix per query) and the same {} test rows as one batch, \
             per row, each repeated for ≥ 50 ms. Best value per column in bold. \
             KNN (distance-weighted) and a deep tree reproduce their training rows by construction, \
             so their train-split columns measure memorisation, not accuracy: judge on the test split.\n\n",
            self.robot,
            o.seed,
            self.entries.first().map_or(0, |e| e.train_task_rows),
            o.timing_queries.min(nt),
        );
        for n in &self.notes {
            s.push_str(n);
            s.push_str("\n\n");
        }
        s.push_str("| learner |");
        for c in &cols {
            s.push_str(&format!(" {} |", c.header));
        }
        s.push_str(" hyper-parameters (chosen on validation) |\n|---|");
        for _ in &cols {
            s.push_str("---:|");
        }
        s.push_str("---|\n");
        let best: Vec<f64> = cols
            .iter()
            .map(|c| {
                self.entries
                    .iter()
                    .map(|e| (c.get)(e))
                    .filter(|v| v.is_finite())
                    .fold(f64::INFINITY, f64::min)
            })
            .collect();
        for e in &self.entries {
            s.push_str(&format!("| {} |", e.name));
            for (c, b) in cols.iter().zip(&best) {
                let v = (c.get)(e);
                let txt = c.shown.text(v);
                if v == *b && self.entries.len() > 1 {
                    s.push_str(&format!(" **{txt}** |"));
                } else {
                    s.push_str(&format!(" {txt} |"));
                }
            }
            s.push_str(&format!(" {} |\n", e.hyper.replace('|', "/")));
        }
        let beats = self.beats();
        if self.reference().is_some() {
            s.push_str(&format!("\n## Where a baseline beats {REFERENCE}\n\n"));
            if beats.is_empty() {
                s.push_str("Nowhere: cascade correlation is best or tied on every column.\n");
            } else {
                for b in beats {
                    s.push_str(&format!("- {b}\n"));
                }
            }
        } else {
            s.push_str(&format!("\n{REFERENCE} did not run in this comparison.\n"));
        }
        s
    }

    /// One CSV row per learner with every column of the table.
    pub fn to_csv(&self) -> String {
        let cols = columns();
        let mut s = String::from("learner");
        for c in &cols {
            s.push(',');
            s.push_str(c.csv);
        }
        s.push_str(",rows_train,rows_test,task_rows_train,task_rows_test,tip_p95_mm_train,tip_max_mm_train,angle_mean_deg_train,failed_solves_train,hyper_parameters\n");
        for e in &self.entries {
            s.push_str(&csv_field(&e.name));
            for c in &cols {
                s.push_str(&format!(",{}", (c.get)(e)));
            }
            s.push_str(&format!(
                ",{},{},{},{},{},{},{},{},{}\n",
                e.train.samples,
                e.test.samples,
                e.train_task_rows,
                e.test.samples,
                e.train.position_mm.p95,
                e.train.position_mm.max,
                e.train.orientation_deg.mean,
                e.train.failed_solves,
                csv_field(&e.hyper)
            ));
        }
        s
    }

    /// Bars for Figure 3.
    pub fn bars(&self) -> Vec<LearnerBars> {
        self.entries
            .iter()
            .map(|e| LearnerBars {
                name: e.name.clone(),
                train_rmse: e.train.tension_rmse_norm100,
                test_rmse: e.test.tension_rmse_norm100,
                tip_mean_mm: e.test.position_mm.mean,
                tip_p95_mm: e.test.position_mm.p95,
            })
            .collect()
    }

    /// Write `compare.md`, `compare.csv` and `compare.png` into `dir` (atomically).
    pub fn write(&self, dir: &Path) -> Result<Vec<PathBuf>, CompareError> {
        let md = dir.join("compare.md");
        let csv = dir.join("compare.csv");
        let png = dir.join("compare.png");
        let werr = |path: &Path, why: String| CompareError::Write {
            path: path.to_path_buf(),
            why,
        };
        std::fs::create_dir_all(dir).map_err(|e| werr(dir, e.to_string()))?;
        crate::fsutil::write_atomic(&md, self.to_markdown().as_bytes())
            .map_err(|e| werr(&md, e.to_string()))?;
        crate::fsutil::write_atomic(&csv, self.to_csv().as_bytes())
            .map_err(|e| werr(&csv, e.to_string()))?;
        let title = format!(
            "{}: IK learners compared (test split: {} rows)",
            self.robot, self.sizes.2
        );
        draw_comparison(&self.bars(), &title, &png).map_err(|e| werr(&png, e.to_string()))?;
        Ok(vec![md, csv, png])
    }
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compare::CompareOptions;
    use crate::evaluate::SplitMetrics;

    fn entry(name: &str, test_rmse: f64, tip: f64) -> Entry {
        let mut test = SplitMetrics {
            samples: 10,
            tension_rmse_norm100: test_rmse,
            tension_rmse_newton: test_rmse / 10.0,
            ..SplitMetrics::default()
        };
        test.position_mm.mean = tip;
        Entry {
            name: name.into(),
            hyper: "h=1".into(),
            parameters: 10,
            train_seconds: 1.0,
            infer_us: 1.0,
            infer_batched_us: 0.5,
            infer_fast_us: None,
            train: test.clone(),
            train_task_rows: 10,
            test,
        }
    }

    fn table(entries: Vec<Entry>) -> Comparison {
        Comparison {
            robot: "r".into(),
            sizes: (80, 10, 10),
            options: CompareOptions::default(),
            entries,
            notes: Vec::new(),
        }
    }

    #[test]
    fn table_says_where_a_baseline_beats_cascade_correlation() {
        let c = table(vec![entry(REFERENCE, 0.5, 1.0), entry("ELM", 0.2, 2.0)]);
        let beats = c.beats();
        assert_eq!(beats.len(), 1, "{beats:?}");
        assert!(
            beats[0].starts_with("ELM beats Cascade correlation on"),
            "{beats:?}"
        );
        assert!(
            beats[0].contains("RMSE×100 test (0.200 vs 0.500)"),
            "{beats:?}"
        );
        assert!(!beats[0].contains("tip mean ("), "{beats:?}");
        let md = c.to_markdown();
        assert!(md.contains("## Where a baseline beats Cascade correlation"));
        assert!(md.contains("| ELM | **0.200** | **0.200** |"), "{md}");
    }

    #[test]
    fn table_says_when_no_baseline_beats_cascade_correlation() {
        let c = table(vec![entry(REFERENCE, 0.1, 0.1), entry("KNN", 0.2, 2.0)]);
        assert!(c.beats().is_empty());
        assert!(c.to_markdown().contains("Nowhere"));
    }

    #[test]
    fn csv_quotes_fields_with_commas() {
        let c = table(vec![entry("KNN", 0.2, 2.0)]);
        let mut e = c.entries[0].clone();
        e.hyper = "k=5, weights=distance".into();
        let c = table(vec![e]);
        assert!(c
            .to_csv()
            .lines()
            .nth(1)
            .unwrap()
            .ends_with(",\"k=5, weights=distance\""));
    }
}
