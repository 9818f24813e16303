//! Polylines: a backbone or a tendon's path resampled to a given number of
//! evenly spaced points (the plant's and the dynamics' scenes).

/// `points` ≥ 2 points evenly spaced along the polyline `line` by its
/// length, its first and last points kept exactly (empty stays empty).
pub fn resample(line: &[nalgebra::Vector3<f64>], points: usize) -> Vec<nalgebra::Vector3<f64>> {
    let (Some(first), Some(last)) = (line.first(), line.last()) else {
        return vec![];
    };
    let points = points.max(2);
    if line.len() < 2 {
        return vec![*first; points];
    }
    let mut along = Vec::with_capacity(line.len());
    let mut total = 0.0;
    along.push(0.0);
    for w in line.windows(2) {
        total += (w[1] - w[0]).norm();
        along.push(total);
    }
    let mut out = Vec::with_capacity(points);
    out.push(*first);
    let mut j = 0;
    for k in 1..points - 1 {
        let target = total * k as f64 / (points - 1) as f64;
        while j + 2 < along.len() && along[j + 1] < target {
            j += 1;
        }
        let span = along[j + 1] - along[j];
        let t = if span > 0.0 {
            (target - along[j]) / span
        } else {
            0.0
        };
        out.push(line[j] + (line[j + 1] - line[j]) * t.clamp(0.0, 1.0));
    }
    out.push(*last);
    out
}
