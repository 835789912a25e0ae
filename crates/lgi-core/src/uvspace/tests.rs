//! Tests of the sewing space: UV islands and the one vertex-UV rule on small grids with seams
//! and holes, barriers, and the 3D proxies against brute-force nearest vertices.

use super::*;

#[test]
fn proxies_equal_brute_force_nearest() {
    let mut s = 7u64;
    let mut rnd = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    let pos: Vec<DVec3> = (0..600)
        .map(|_| DVec3::new(rnd(), rnd(), rnd() * 0.3))
        .collect();
    let in_space: Vec<bool> = pos.iter().map(|p| p.x < 0.6).collect();
    let inside: Vec<u32> = (0..600).filter(|&v| in_space[v as usize]).collect();
    let got = proxies(&pos, &in_space, &inside);
    for v in 0..600 {
        if in_space[v] {
            assert_eq!(got[v] as usize, v);
            continue;
        }
        let want = inside
            .iter()
            .copied()
            .min_by(|&a, &b| {
                pos[v]
                    .distance_squared(pos[a as usize])
                    .total_cmp(&pos[v].distance_squared(pos[b as usize]))
                    .then(a.cmp(&b))
            })
            .unwrap();
        assert_eq!(got[v], want, "vertex {v}");
    }
}

/// An n×n grid of unit quads in the z = 0 plane, UV = position / n. `hole` removes a quad;
/// `island` gives a quad its own four UVs (offset by 2 in u), like ICT's mouth socket.
fn grid_mesh(n: u32, hole: Option<(u32, u32)>, island: Option<(u32, u32)>) -> Mesh {
    let mut m = Mesh::default();
    for j in 0..=n {
        for i in 0..=n {
            m.positions.push(glam::DVec3::new(i as f64, j as f64, 0.0));
            m.uvs.push(DVec2::new(i as f64, j as f64) / n as f64);
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    for j in 0..n {
        for i in 0..n {
            if hole == Some((i, j)) {
                continue;
            }
            let v = [id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)];
            let u = if island == Some((i, j)) {
                let base = m.uvs.len() as u32;
                for &k in &v {
                    let p = m.uvs[k as usize];
                    m.uvs.push(p + DVec2::new(2.0, 0.0));
                }
                [base, base + 1, base + 2, base + 3]
            } else {
                v
            };
            m.triangles.push([v[0], v[1], v[2]]);
            m.triangles.push([v[0], v[2], v[3]]);
            m.uv_triangles.push([u[0], u[1], u[2]]);
            m.uv_triangles.push([u[0], u[2], u[3]]);
        }
    }
    m
}

/// Barriers as sorted, direction-free integer keys (coordinates × 3 rounded).
fn keys(b: &[Barrier]) -> Vec<[(i64, i64); 2]> {
    let k = |p: DVec2| ((p.x * 3.0).round() as i64, (p.y * 3.0).round() as i64);
    let mut out: Vec<_> = b
        .iter()
        .map(|s| {
            let (a, c) = (k(s[0]), k(s[1]));
            if a <= c {
                [a, c]
            } else {
                [c, a]
            }
        })
        .collect();
    out.sort();
    out
}

/// Unit edges of the rim of the 3×3 grid, as keys.
fn rim() -> Vec<[(i64, i64); 2]> {
    let mut r = Vec::new();
    for i in 0..3 {
        r.push([(i, 0), (i + 1, 0)]);
        r.push([(i, 3), (i + 1, 3)]);
        r.push([(0, i), (0, i + 1)]);
        r.push([(3, i), (3, i + 1)]);
    }
    r
}

/// The rim plus the four edges around the hole at cell (1, 1) of the 3×3 grid.
fn rim_and_hole() -> Vec<[(i64, i64); 2]> {
    let mut r = rim();
    r.extend([
        [(1, 1), (2, 1)],
        [(1, 2), (2, 2)],
        [(1, 1), (1, 2)],
        [(2, 1), (2, 2)],
    ]);
    r
}

fn sorted(mut v: Vec<[(i64, i64); 2]>) -> Vec<[(i64, i64); 2]> {
    v.sort();
    v
}

#[test]
fn boundary_barriers_are_the_rim_and_the_hole() {
    let m = grid_mesh(3, Some((1, 1)), None);
    let uv = vertex_charts(&m);
    let expect = rim_and_hole();
    assert_eq!(keys(&boundary_barriers(&m, &uv)), sorted(expect));
}

#[test]
fn vertex_uvs_take_the_lowest_triangle_of_the_space_on_seams() {
    let m = grid_mesh(3, None, Some((1, 1)));
    let islands = UvIslands::new(&m);
    assert_eq!(islands.island_size, vec![16, 2]);
    // Asked about the big island only (as the sewing space asks about the islands carrying
    // bundles), the island quad's corners take the big island's UVs.
    let big = islands.vertex_uvs(&m, |i| i == 0);
    for (v, p) in m.positions.iter().enumerate() {
        assert_eq!(big[v], Some(DVec2::new(p.x, p.y) / 3.0));
    }
    // Over all islands the lowest triangle decides: vertex 10, corner (2, 2), is first
    // used by the island quad (triangle 8); the quad's other corners by the big island.
    let uv = vertex_charts(&m);
    for (v, p) in m.positions.iter().enumerate() {
        let offset = if v == 10 {
            DVec2::new(2.0, 0.0)
        } else {
            DVec2::ZERO
        };
        assert_eq!(uv[v], DVec2::new(p.x, p.y) / 3.0 + offset, "vertex {v}");
    }
    // A seam is not a 3D boundary: only the rim.
    assert_eq!(keys(&boundary_barriers(&m, &uv)), sorted(rim()));
    // The big island's own boundary closes the hole the small island fills.
    let expect = rim_and_hole();
    assert_eq!(keys(&islands.island_barriers(&m, 0)), sorted(expect));
    // The small island's boundary lies in its own UVs (offset by 2 = 6/3 in u).
    assert_eq!(
        keys(&islands.island_barriers(&m, 1)),
        sorted(vec![
            [(7, 1), (8, 1)],
            [(7, 2), (8, 2)],
            [(7, 1), (7, 2)],
            [(8, 1), (8, 2)]
        ])
    );
}

#[test]
fn boundary_barriers_skip_edges_across_charts() {
    // The corner quad is its own island with the lowest triangles: its four corners map
    // into it, so its two rim edges are barriers in its own UVs (offset by 2 = 6/3 in u),
    // while the next rim edges, whose corners lie in the big island, would join unrelated
    // UV points.
    let m = grid_mesh(3, None, Some((0, 0)));
    let uv = vertex_charts(&m);
    assert_eq!(uv[0], DVec2::new(2.0, 0.0));
    let across = [
        [(0, 0), (1, 0)],
        [(1, 0), (2, 0)],
        [(0, 0), (0, 1)],
        [(0, 1), (0, 2)],
    ];
    let mut expect: Vec<_> = rim().into_iter().filter(|e| !across.contains(e)).collect();
    expect.extend([[(6, 0), (7, 0)], [(6, 0), (6, 1)]]);
    assert_eq!(keys(&boundary_barriers(&m, &uv)), sorted(expect));
}

#[test]
fn vertex_uvs_take_the_lowest_triangle_and_unused_vertices_are_nan() {
    // Two triangles sharing vertex 0, each its own one-triangle island; vertex 4 is unused.
    let m = Mesh {
        positions: vec![DVec3::ZERO; 5],
        triangles: vec![[0, 1, 2], [0, 2, 3]],
        uvs: [
            (0.0, 0.0),
            (1.0, 0.0),
            (1.0, 1.0),
            (5.0, 5.0),
            (6.0, 6.0),
            (5.0, 6.0),
        ]
        .map(|(u, v)| DVec2::new(u, v))
        .to_vec(),
        uv_triangles: vec![[0, 1, 2], [3, 4, 5]],
    };
    let islands = UvIslands::new(&m);
    assert_eq!(islands.triangle_island, vec![0, 1]);
    let uv = vertex_charts(&m);
    assert_eq!(uv[0], DVec2::new(0.0, 0.0));
    assert_eq!(uv[2], DVec2::new(1.0, 1.0));
    assert_eq!(uv[3], DVec2::new(5.0, 6.0));
    assert!(uv[4].is_nan());
    // Asked about the second island only, the shared vertices take its UVs.
    let second = islands.vertex_uvs(&m, |i| i == 1);
    assert_eq!(second[0], Some(DVec2::new(5.0, 5.0)));
    assert_eq!(second[1], None);
    assert_eq!(second[2], Some(DVec2::new(6.0, 6.0)));
    assert_eq!(second[4], None);
    let no_uv = Mesh {
        uvs: Vec::new(),
        uv_triangles: Vec::new(),
        ..m
    };
    assert!(vertex_charts(&no_uv).iter().all(|p| p.is_nan()));
}
