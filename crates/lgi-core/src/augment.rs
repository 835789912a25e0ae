//! Deterministic dataset augmentation: in-betweens and pairwise combinations of a dataset's
//! shapes. Used to make the large "ICT-300" benchmark workload from the 57 ICT shapes, and
//! available to users whose datasets hold only extreme poses.

use crate::dataset::Dataset;
use crate::error::{LgiError, Result};

/// Shape-name prefixes of the upper and lower face (ARKit naming).
const UPPER: [&str; 4] = ["brow", "eye", "cheekSquint", "noseSneer"];
const LOWER: [&str; 3] = ["mouth", "jaw", "cheekPuff"];

/// One augmented shape: a name and a linear combination of original shapes.
pub type Recipe = (String, Vec<(usize, f32)>);

/// The recipes of [`augment`], in order: originals, in-betweens at 0.25/0.5/0.75, left+right
/// pairs (`x_L` with `x_R`), then upper+lower face pairs until `min_shapes` is reached (and
/// if still short, pairs of any two shapes in index order).
pub fn recipes(names: &[String], min_shapes: usize) -> Vec<Recipe> {
    let mut out: Vec<Recipe> = names
        .iter()
        .enumerate()
        .map(|(k, n)| (n.clone(), vec![(k, 1.0)]))
        .collect();
    for (k, n) in names.iter().enumerate() {
        for w in [0.25f32, 0.5, 0.75] {
            out.push((format!("{n}@{w}"), vec![(k, w)]));
        }
    }
    for (k, n) in names.iter().enumerate() {
        if let Some(base) = n.strip_suffix("_L") {
            if let Some(r) = names.iter().position(|m| *m == format!("{base}_R")) {
                out.push((format!("{base}_LR"), vec![(k, 1.0), (r, 1.0)]));
            }
        }
    }
    let has = |n: &str, p: &[&str]| p.iter().any(|q| n.starts_with(q));
    let upper: Vec<usize> = (0..names.len())
        .filter(|&k| has(&names[k], &UPPER))
        .collect();
    let lower: Vec<usize> = (0..names.len())
        .filter(|&k| has(&names[k], &LOWER))
        .collect();
    // Interleave so a truncated list still spans many upper and lower shapes.
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    for d in 0..lower.len() {
        for (i, &u) in upper.iter().enumerate() {
            pairs.push((u, lower[(i + d) % lower.len()]));
        }
    }
    let n = names.len();
    pairs.extend((0..n).flat_map(|a| ((a + 1)..n).map(move |b| (a, b))));
    for (a, b) in pairs {
        if out.len() >= min_shapes {
            break;
        }
        let name = format!("{}+{}", names[a], names[b]);
        if out.iter().any(|(m, _)| *m == name) {
            continue;
        }
        out.push((name, vec![(a, 1.0), (b, 1.0)]));
    }
    out
}

/// A new dataset with the shapes of [`recipes`] (at least `min_shapes` when the dataset has
/// enough pairs). The neutral and topology are shared with `dataset`.
pub fn augment(dataset: &Dataset, min_shapes: usize) -> Result<Dataset> {
    if dataset.num_shapes() == 0 {
        return Err(LgiError::Dataset(
            "cannot augment a dataset without shapes".into(),
        ));
    }
    let rec = recipes(dataset.names(), min_shapes);
    let n3 = dataset.num_vertices() * 3;
    let mut disp = vec![0.0f32; rec.len() * n3];
    for (out, (_, terms)) in disp.chunks_mut(n3).zip(&rec) {
        for &(k, w) in terms {
            for (o, s) in out.iter_mut().zip(dataset.shape(k)) {
                *o += w * s;
            }
        }
    }
    let names = rec.into_iter().map(|(n, _)| n).collect();
    let out = Dataset::new(dataset.neutral().clone(), disp, names)?;
    match dataset.polygons() {
        Some(p) => out.with_polygons(p.clone()),
        None => Ok(out),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recipes_cover_inbetweens_pairs_and_reach_the_requested_count() {
        let names: Vec<String> = ["browDown_L", "browDown_R", "jawOpen", "mouthSmile_L"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let r = recipes(&names, 30);
        assert_eq!(r[0], ("browDown_L".to_string(), vec![(0, 1.0)]));
        assert!(r
            .iter()
            .any(|(n, t)| n == "jawOpen@0.5" && t == &vec![(2, 0.5)]));
        assert!(r
            .iter()
            .any(|(n, t)| n == "browDown_LR" && t == &vec![(0, 1.0), (1, 1.0)]));
        assert!(r.iter().any(|(n, _)| n == "browDown_L+jawOpen"));
        // 4 + 12 + 1 + all 6 distinct pairs (one repeats the _LR sum under another name).
        assert_eq!(r.len(), 4 + 12 + 1 + 6);
        let unique: std::collections::HashSet<_> = r.iter().map(|(n, _)| n).collect();
        assert_eq!(unique.len(), r.len());
    }
}
