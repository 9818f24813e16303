//! `tendril ik`: tensions for a tip pose through a `.tnet` net, decoded by the
//! same `tendril-shared` decoder and evaluated by the same f32 `infer` as the
//! firmware, so host and MCU agree bit for bit.

use std::path::PathBuf;

use anyhow::{bail, Context};

use crate::dataset::POSE_COLUMNS;
use crate::learn::cascor::export::{infer, read_tnet};

/// Inverse kinematics: tip pose → tendon tensions (N) with a trained net.
#[derive(clap::Args, Debug)]
pub struct IkArgs {
    /// Weight file written by `tendril train`.
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// One pose: px,py,pz,qw,qx,qy,qz (m, unit quaternion w first).
    #[arg(
        long,
        value_name = "POSE",
        allow_hyphen_values = true,
        conflicts_with = "input"
    )]
    pub pose: Option<String>,
    /// Print `{"tensions":[...]}` instead of plain numbers.
    #[arg(long)]
    pub json: bool,
    /// Batch input CSV with columns px,py,pz,qw,qx,qy,qz (others ignored).
    #[arg(long, value_name = "CSV", requires = "output")]
    pub input: Option<PathBuf>,
    /// Batch output CSV: t0..t{T-1} (N), one row per input row; written atomically.
    #[arg(long, value_name = "CSV", requires = "input")]
    pub output: Option<PathBuf>,
}

fn parse_pose(text: &str) -> anyhow::Result<[f64; 7]> {
    let v = super::common::parse_list(text, "--pose")?;
    if v.len() != 7 {
        bail!(
            "--pose needs 7 numbers px,py,pz,qw,qx,qy,qz, got {}",
            v.len()
        );
    }
    if v.iter().any(|x| !x.is_finite()) {
        bail!("--pose has a non-finite number");
    }
    let mut p = [0.0; 7];
    p.copy_from_slice(&v);
    Ok(p)
}

/// Run `tendril ik`.
pub fn run(a: IkArgs) -> anyhow::Result<()> {
    let net = read_tnet(&a.model)?;
    let outputs = net.shape().outputs;
    if let Some(text) = &a.pose {
        let pose = parse_pose(text)?;
        let t = infer(&net, &pose);
        if a.json {
            println!("{}", serde_json::json!({ "tensions": t }));
        } else {
            let s: Vec<String> = t.iter().map(|x| x.to_string()).collect();
            println!("{}", s.join(","));
        }
        return Ok(());
    }
    let (Some(input), Some(output)) = (&a.input, &a.output) else {
        bail!("give --pose px,py,pz,qw,qx,qy,qz or --input poses.csv --output tensions.csv");
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(true)
        .from_path(input)
        .with_context(|| format!("{}: cannot open", input.display()))?;
    let header: Vec<String> = reader
        .headers()
        .with_context(|| format!("{}: unreadable header", input.display()))?
        .iter()
        .map(|s| s.trim().to_string())
        .collect();
    let cols: Vec<usize> = POSE_COLUMNS
        .iter()
        .map(|c| {
            header.iter().position(|h| h == c).with_context(|| {
                format!(
                    "{}: missing column {c} (need px,py,pz,qw,qx,qy,qz)",
                    input.display()
                )
            })
        })
        .collect::<anyhow::Result<_>>()?;
    let mut rows = Vec::new();
    for (i, rec) in reader.records().enumerate() {
        let rec = rec.with_context(|| format!("{}: row {}", input.display(), i + 2))?;
        let mut pose = [0.0; 7];
        for (k, &c) in cols.iter().enumerate() {
            let s = rec.get(c).unwrap_or("").trim();
            pose[k] = s
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .with_context(|| {
                    format!(
                        "{}: row {}, column {}: {s:?} is not a finite number",
                        input.display(),
                        i + 2,
                        POSE_COLUMNS[k]
                    )
                })?;
        }
        rows.push(infer(&net, &pose));
    }
    crate::fsutil::write_atomic_with(output, |w| {
        let head: Vec<String> = (0..outputs).map(|i| format!("t{i}")).collect();
        writeln!(w, "{}", head.join(","))?;
        for t in &rows {
            let s: Vec<String> = t.iter().map(|x| x.to_string()).collect();
            writeln!(w, "{}", s.join(","))?;
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", output.display()))?;
    eprintln!("wrote {} ({} rows)", output.display(), rows.len());
    Ok(())
}
