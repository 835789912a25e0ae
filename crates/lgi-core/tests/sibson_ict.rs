//! Sibson weights on the real ICT-FaceKit face: the 120 markers in the face chart's UVs, with the
//! chart's own boundary (mouth, eyes, rim) as barriers. Checks that no weight leaks across the
//! mouth or the eyes and that the lips follow jawOpen; skipped when the data is absent.

use lgi_core::{
    boundary_barriers, closest_point_on_triangle, interpolate3, vertex_charts, Barrier, DVec2,
    DVec3, Mesh, SibsonWeights, SparseWeights, UvIslands,
};
use std::collections::{BinaryHeap, HashMap};
mod common;

use std::time::Instant;

use common::ict_dir;

/// Minimal OBJ reading (positions, UVs, polygon fans): this test must not depend on the
/// project's reader.
fn read_obj(path: &std::path::Path) -> Mesh {
    let text = std::fs::read_to_string(path).unwrap();
    let mut m = Mesh::default();
    for line in text.lines() {
        let mut it = line.split_whitespace();
        match it.next() {
            Some("v") => {
                let c: Vec<f64> = it.take(3).map(|s| s.parse().unwrap()).collect();
                m.positions.push(DVec3::new(c[0], c[1], c[2]));
            }
            Some("vt") => {
                let c: Vec<f64> = it.take(2).map(|s| s.parse().unwrap()).collect();
                m.uvs.push(DVec2::new(c[0], c[1]));
            }
            Some("f") => {
                let corners: Vec<(u32, u32)> = it
                    .map(|s| {
                        let mut p = s.split('/');
                        let v: u32 = p.next().unwrap().parse().unwrap();
                        let t: u32 = p.next().unwrap().parse().unwrap();
                        (v - 1, t - 1)
                    })
                    .collect();
                for k in 1..corners.len() - 1 {
                    let (a, b, c) = (corners[0], corners[k], corners[k + 1]);
                    m.triangles.push([a.0, b.0, c.0]);
                    m.uv_triangles.push([a.1, b.1, c.1]);
                }
            }
            _ => {}
        }
    }
    m
}

fn read_markers(path: &std::path::Path) -> Vec<DVec3> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let c: Vec<f64> = l.split(',').skip(1).map(|s| s.parse().unwrap()).collect();
            DVec3::new(c[0], c[1], c[2])
        })
        .collect()
}

/// A marker on the surface (optionally only the flagged triangles): its triangle and
/// barycentrics (brute-force closest point).
fn locate(mesh: &Mesh, p: DVec3, only: Option<&[bool]>) -> (usize, [f64; 3]) {
    let mut best = (f64::INFINITY, 0, [0.0; 3]);
    for t in 0..mesh.triangles.len() {
        if only.is_some_and(|o| !o[t]) {
            continue;
        }
        let [a, b, c] = mesh.triangle(t);
        let (q, bary) = closest_point_on_triangle(p, a, b, c);
        let d = (q - p).length_squared();
        if d < best.0 {
            best = (d, t, bary);
        }
    }
    (best.1, best.2)
}

/// Shortest paths along the edges of the given triangles, from one source, up to `limit`.
fn dijkstra(adj: &[Vec<(u32, f64)>], source: u32, limit: f64) -> HashMap<u32, f64> {
    #[derive(PartialEq)]
    struct Item(f64, u32);
    impl Eq for Item {}
    impl PartialOrd for Item {
        fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
            Some(self.cmp(o))
        }
    }
    impl Ord for Item {
        fn cmp(&self, o: &Self) -> std::cmp::Ordering {
            o.0.total_cmp(&self.0)
        }
    }
    let mut dist = HashMap::new();
    let mut heap = BinaryHeap::from([Item(0.0, source)]);
    while let Some(Item(d, v)) = heap.pop() {
        if dist.contains_key(&v) || d > limit {
            continue;
        }
        dist.insert(v, d);
        for &(w, l) in &adj[v as usize] {
            if !dist.contains_key(&w) {
                heap.push(Item(d + l, w));
            }
        }
    }
    dist
}

/// Connected components of a set of segments (shared endpoints), as lists of segment indices.
fn loops(b: &[Barrier]) -> Vec<Vec<usize>> {
    let key = |p: DVec2| (p.x.to_bits(), p.y.to_bits());
    let mut parent: Vec<usize> = (0..b.len()).collect();
    fn find(p: &mut [usize], mut a: usize) -> usize {
        while p[a] != a {
            p[a] = p[p[a]];
            a = p[a];
        }
        a
    }
    let mut first: HashMap<(u64, u64), usize> = HashMap::new();
    for (k, s) in b.iter().enumerate() {
        for p in s {
            let f = *first.entry(key(*p)).or_insert(k);
            let (ra, rb) = (find(&mut parent, f), find(&mut parent, k));
            parent[ra] = rb;
        }
    }
    let mut groups: HashMap<usize, Vec<usize>> = HashMap::new();
    for k in 0..b.len() {
        let r = find(&mut parent, k);
        groups.entry(r).or_default().push(k);
    }
    groups.into_values().collect()
}

#[test]
fn ict_face_weights_do_not_leak_across_mouth_and_eyes() {
    let Some(dir) = ict_dir() else {
        eprintln!("ICT-FaceKit data not found (set LGI_SHARED_DATA): skipped");
        return;
    };
    let mesh = read_obj(&dir.join("generic_neutral_mesh.obj"));
    mesh.validate("ICT neutral").unwrap();
    let markers = read_markers(&dir.join("markers_120.csv"));
    let islands = UvIslands::new(&mesh);
    let charts = vertex_charts(&mesh);
    assert_eq!(charts.len(), mesh.num_vertices());

    // The face chart is the island most markers fall on; markers are then located on it only:
    // a marker on the face/head seam may be closest to a head triangle, whose UVs live in
    // another (overlapping) chart.
    let nearest: Vec<usize> = markers.iter().map(|&p| locate(&mesh, p, None).0).collect();
    let mut votes: HashMap<u32, usize> = HashMap::new();
    for &t in &nearest {
        *votes.entry(islands.triangle_island[t]).or_default() += 1;
    }
    let (&face, &n_face) = votes
        .iter()
        .max_by_key(|&(i, n)| (*n, std::cmp::Reverse(*i)))
        .unwrap();
    assert!(n_face >= 110, "most markers lie on one chart: {votes:?}");
    let face_tris: Vec<bool> = islands.triangle_island.iter().map(|&i| i == face).collect();
    let located: Vec<(usize, [f64; 3])> = markers
        .iter()
        .map(|&p| locate(&mesh, p, Some(&face_tris)))
        .collect();
    let off_chart = markers
        .iter()
        .zip(&located)
        .map(|(&p, &(t, w))| (interpolate3(mesh.triangle(t), w) - p).length())
        .fold(0.0, f64::max);
    // One ICT marker sits ~1 mm past the face/head seam.
    assert!(
        off_chart < 0.2,
        "markers lie on the face chart ({off_chart} cm)"
    );
    let site_uv: Vec<DVec2> = located
        .iter()
        .map(|&(t, w)| {
            let u = mesh.uv_triangles[t].map(|i| mesh.uvs[i as usize]);
            u[0] * w[0] + u[1] * w[1] + u[2] * w[2]
        })
        .collect();
    // The face chart's vertices and their UVs, by the sewing space's rule with the face
    // island as the space.
    let face_uvs = islands.vertex_uvs(&mesh, |i| i == face);
    let face_vertices: Vec<u32> = (0..mesh.num_vertices() as u32)
        .filter(|&v| face_uvs[v as usize].is_some())
        .collect();
    let queries: Vec<DVec2> = face_uvs.iter().flatten().copied().collect();

    let barriers = islands.island_barriers(&mesh, face);
    let groups = loops(&barriers);
    let in_face_chart = boundary_barriers(&mesh, &charts)
        .iter()
        .filter(|b| {
            // Inside the face chart's UV box: 3D-boundary barriers that could affect it.
            let (lo, hi) = (DVec2::new(0.11, 0.12), DVec2::new(0.89, 0.92));
            b.iter().all(|p| p.cmpge(lo).all() && p.cmple(hi).all())
        })
        .count();
    eprintln!(
        "ICT: {} islands, face island {} ({} triangles, {} vertices; {} of 120 markers nearest to it), \
         {} chart-boundary barriers in {} loops; {} 3D-boundary barriers fall inside the face chart's UV box",
        islands.island_size.len(),
        face,
        islands.island_size[face as usize],
        face_vertices.len(),
        n_face,
        barriers.len(),
        groups.len(),
        in_face_chart
    );

    let with = SibsonWeights::new(&site_uv, &barriers).unwrap();
    let without = SibsonWeights::new(&site_uv, &[]).unwrap();
    let time = |sw: &SibsonWeights| {
        let mut best = f64::INFINITY;
        let mut w = None;
        for _ in 0..5 {
            let t = Instant::now();
            w = Some(sw.weights(&queries));
            best = best.min(t.elapsed().as_secs_f64() * 1e3);
        }
        (w.unwrap(), best)
    };
    let (w_with, ms_with) = time(&with);
    let (w_without, ms_without) = time(&without);
    eprintln!(
        "ICT weights(): {} queries x 120 sites: {:.2} ms with {} barriers, {:.2} ms without (best of 5)",
        queries.len(),
        ms_with,
        barriers.len(),
        ms_without
    );
    for r in 0..w_with.num_rows() {
        let s: f64 = w_with.row(r).1.iter().sum();
        assert!((s - 1.0).abs() < 1e-12);
    }

    // Leak check, independent of UVs: a weight from bundle i on vertex v is a leak when the
    // path over the face surface from v to the bundle is much longer than the straight 3D
    // distance (the path must go round the mouth corner or the eye).
    let mut adj: Vec<Vec<(u32, f64)>> = vec![Vec::new(); mesh.num_vertices()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if islands.triangle_island[t] != face {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let l = (mesh.positions[a as usize] - mesh.positions[b as usize]).length();
            adj[a as usize].push((b, l));
            adj[b as usize].push((a, l));
        }
    }
    let from_marker: Vec<HashMap<u32, f64>> = located
        .iter()
        .zip(&markers)
        .map(|(&(t, _), &m)| {
            let v = *mesh.triangles[t]
                .iter()
                .min_by(|&&a, &&b| {
                    let d = |v: u32| (mesh.positions[v as usize] - m).length();
                    d(a).total_cmp(&d(b))
                })
                .unwrap();
            let offset = (mesh.positions[v as usize] - m).length();
            dijkstra(&adj, v, 30.0)
                .into_iter()
                .map(|(k, d)| (k, d + offset))
                .collect()
        })
        .collect();
    // (number of pairs over the bound, their total weight, worst ratio, bundles involved)
    let leaks = |w: &SparseWeights, bound: f64| {
        let (mut over, mut mass, mut worst) = (0usize, 0.0f64, 0.0f64);
        let mut bundles = std::collections::BTreeSet::new();
        for (r, &v) in face_vertices.iter().enumerate() {
            let p = mesh.positions[v as usize];
            let (cols, vals) = w.row(r);
            for (&i, &x) in cols.iter().zip(vals) {
                // Floor: the surface path starts at the marker triangle's nearest corner.
                let straight = (p - markers[i as usize]).length().max(0.3);
                let path = from_marker[i as usize]
                    .get(&v)
                    .copied()
                    .unwrap_or(f64::INFINITY);
                let ratio = path / straight;
                worst = worst.max(ratio);
                if ratio > bound {
                    over += 1;
                    mass += x;
                    bundles.insert(i);
                }
            }
        }
        (over, mass, worst, bundles)
    };
    const BOUND: f64 = 3.0;
    let (over_with, mass_with, worst_with, b_with) = leaks(&w_with, BOUND);
    let (over_without, mass_without, worst_without, b_without) = leaks(&w_without, BOUND);
    eprintln!(
        "ICT weighted (vertex, bundle) pairs whose surface path is over {BOUND}x the straight 3D \
         distance: {over_with} (weight {mass_with:.2}, worst ratio {worst_with:.2}, bundles {b_with:?}) \
         with barriers; {over_without} (weight {mass_without:.2}, worst {worst_without:.2}, bundles \
         {b_without:?}) without"
    );
    // The lips leak badly without barriers. With them, what remains is the mouth corner: the
    // inner-lip loop (the UV slit) ends medially of the lips' outer surface in UV, so lip
    // vertices near a corner still see the opposite lip's corner bundle past the slit's end.
    assert!(over_without > 200 && worst_without > 10.0);
    assert!(5 * over_with < over_without && 4.0 * mass_with < mass_without);
    assert!(worst_with < 0.6 * worst_without);

    // jawOpen at the mouth rim: the rim vertices' displacement predicted from the bundles'.
    let open = read_obj(&dir.join("shapes/jawOpen.obj"));
    assert_eq!(open.positions.len(), mesh.positions.len());
    let disp = |t: usize, w: [f64; 3]| {
        let tri =
            mesh.triangles[t].map(|v| open.positions[v as usize] - mesh.positions[v as usize]);
        interpolate3(tri, w)
    };
    let bundle_disp: Vec<DVec3> = located.iter().map(|&(t, w)| disp(t, w)).collect();
    let mouth = groups
        .iter()
        .find(|g| {
            let c: DVec2 = g.iter().map(|&k| barriers[k][0]).sum::<DVec2>() / g.len() as f64;
            // The mouth is the loop below the eyes, centred in u.
            (c.x - 0.5).abs() < 0.05 && c.y < 0.55
        })
        .expect("a mouth loop in the face chart's boundary");
    let rim_uv: Vec<DVec2> = mouth.iter().map(|&k| barriers[k][0]).collect();
    let rim: Vec<usize> = face_vertices
        .iter()
        .enumerate()
        .filter(|&(_, &v)| rim_uv.contains(&charts[v as usize]))
        .map(|(r, _)| r)
        .collect();
    let err = |w: &SparseWeights| {
        let mut sum = 0.0;
        for &r in &rim {
            let v = face_vertices[r] as usize;
            let (c, x) = w.row(r);
            let pred: DVec3 = c
                .iter()
                .zip(x)
                .map(|(&i, &x)| bundle_disp[i as usize] * x)
                .sum();
            sum += (pred - (open.positions[v] - mesh.positions[v])).length();
        }
        sum / rim.len() as f64
    };
    let (e_with, e_without) = (err(&w_with), err(&w_without));
    eprintln!(
        "ICT jawOpen, {} mouth-rim vertices: mean displacement error {e_with:.3} cm with barriers, \
         {e_without:.3} cm without",
        rim.len()
    );
    assert!(e_with < e_without);
}
