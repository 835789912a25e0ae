//! Temporal smoothing: a centred moving average of each bundle's shape weights over a window
//! of frames. Choices are made in the jaw-unskinned space, so averaging them does not smooth
//! the jaw's motion; the residual pass afterwards still puts every marker on its target.

use crate::choose::Choice;
use crate::sew::Pieces;

/// Averages each bundle's sparse shape weights over `window` frames centred on each frame
/// (shrinking at the ends; frames where the bundle is missing are skipped). A bundle missing
/// in a frame stays missing there. (Tests only: the model always smooths in bins.)
#[cfg(test)]
pub fn smooth_choices(choices: &[Vec<Option<Choice>>], window: usize) -> Vec<Pieces> {
    smooth_choices_in_bins(choices, &vec![0; choices.len()], window)
}

/// As [`smooth_choices`] for frames looked up in jaw bins (`bins[f]`, choices in each bin's
/// local shape ids): a frame averages only over the window's frames in its own bin, since
/// shape ids of different bins name different shapes.
pub fn smooth_choices_in_bins(
    choices: &[Vec<Option<Choice>>],
    bins: &[usize],
    window: usize,
) -> Vec<Pieces> {
    let nf = choices.len();
    let half = window / 2;
    let mut out = Vec::with_capacity(nf);
    let mut acc: Vec<(u32, f64)> = Vec::new();
    for f in 0..nf {
        let nb = choices[f].len();
        let mut p = Pieces {
            start: vec![0],
            ..Pieces::default()
        };
        for b in 0..nb {
            if choices[f][b].is_some() {
                acc.clear();
                let mut count = 0.0;
                let lo = f.saturating_sub(half);
                let hi = (f + half + 1).min(nf);
                for (g, frame) in choices[lo..hi].iter().enumerate() {
                    if bins.get(lo + g) != bins.get(f) {
                        continue;
                    }
                    let Some(c) = frame.get(b).and_then(|c| c.as_ref()) else {
                        continue;
                    };
                    count += 1.0;
                    for j in 0..4 {
                        if c.weights[j] != 0.0 {
                            match acc.iter_mut().find(|(s, _)| *s == c.shapes[j]) {
                                Some(e) => e.1 += c.weights[j],
                                None => acc.push((c.shapes[j], c.weights[j])),
                            }
                        }
                    }
                }
                acc.sort_by_key(|e| e.0);
                for &(s, w) in &acc {
                    p.shapes.push(s);
                    p.weights.push(w / count);
                }
            }
            p.start.push(p.shapes.len() as u32);
        }
        out.push(p);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::choose::NO_TET;

    fn pure(shape: u32) -> Option<Choice> {
        Some(Choice {
            shapes: [shape, 0, 0, 0],
            weights: [1.0, 0.0, 0.0, 0.0],
            tet: NO_TET,
            projected: false,
            distance: 0.0,
            fit: false,
        })
    }

    #[test]
    fn window_three_averages_neighbouring_frames_and_shrinks_at_the_ends() {
        let frames = vec![vec![pure(1)], vec![pure(2)], vec![pure(2)], vec![None]];
        let p = smooth_choices(&frames, 3);
        assert_eq!(p[0].bundle(0), (&[1u32, 2][..], &[0.5, 0.5][..]));
        let (s, w) = p[1].bundle(0);
        assert_eq!(s, &[1, 2]);
        assert!((w[0] - 1.0 / 3.0).abs() < 1e-15 && (w[1] - 2.0 / 3.0).abs() < 1e-15);
        // Frame 2's window holds frame 3, where the bundle is missing: it is skipped.
        assert_eq!(p[2].bundle(0), (&[2u32][..], &[1.0][..]));
        assert_eq!(p[3].bundle(0).0.len(), 0);
    }

    #[test]
    fn smoothed_weights_stay_convex() {
        let frames: Vec<Vec<Option<Choice>>> =
            (0..9).map(|f| vec![pure(f % 3 + 1), pure(7)]).collect();
        for p in smooth_choices(&frames, 5) {
            for b in 0..2 {
                let (_, w) = p.bundle(b);
                assert!((w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
                assert!(w.iter().all(|&x| x > 0.0));
            }
        }
    }

    #[test]
    fn binned_smoothing_averages_only_frames_of_the_same_bin() {
        // Frames 0..5 in bins 0, 0, 1, 1, 0: shape id 2 in bin 1 is another shape than in bin 0.
        let frames = vec![
            vec![pure(1)],
            vec![pure(2)],
            vec![pure(2)],
            vec![pure(3)],
            vec![pure(1)],
        ];
        let bins = [0, 0, 1, 1, 0];
        let p = smooth_choices_in_bins(&frames, &bins, 3);
        // Frame 1 (bin 0) sees frames 0 and 1 only; frame 2 (bin 1) sees 2 and 3.
        assert_eq!(p[1].bundle(0), (&[1u32, 2][..], &[0.5, 0.5][..]));
        assert_eq!(p[2].bundle(0), (&[2u32, 3][..], &[0.5, 0.5][..]));
        // Frame 4 (bin 0) has no bin-0 neighbour in its window: its own choice.
        assert_eq!(p[4].bundle(0), (&[1u32][..], &[1.0][..]));
        // One bin everywhere is the unbinned average.
        assert_eq!(
            smooth_choices_in_bins(&frames, &[0; 5], 3),
            smooth_choices(&frames, 3)
        );
    }
}
