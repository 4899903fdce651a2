//! Triangle meshes: the template, the phantom, ground-truth surfaces and reconstructions.

use nalgebra::{Point3, Vector3};

/// An indexed triangle mesh in millimetres with per-vertex normals.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions, mm.
    pub vertices: Vec<Point3<f64>>,
    /// Counter-clockwise triangles (outward normal by the right-hand rule).
    pub triangles: Vec<[u32; 3]>,
    /// Unit vertex normals, area-weighted from the faces; same length as `vertices`.
    pub normals: Vec<Vector3<f64>>,
}

/// Why a mesh cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum MeshError {
    /// No triangles.
    #[error("mesh has no triangles")]
    Empty,
    #[error(
        "triangle {triangle} refers to vertex {index}, but the mesh has {vertex_count} vertices"
    )]
    /// A triangle indexes a vertex that does not exist.
    IndexOutOfRange {
        /// The triangle.
        triangle: usize,
        /// The vertex index.
        index: u32,
        /// Vertices in the mesh.
        vertex_count: usize,
    },
    /// A vertex coordinate is NaN or infinite.
    #[error("vertex {index} has a non-finite coordinate ({value})")]
    NonFinite {
        /// The vertex.
        index: usize,
        /// The coordinate.
        value: f64,
    },
    /// A vertex lies too far out for its corners to be welded at the tolerance (the weld keys
    /// are whole multiples of it): not a mesh in millimetres.
    #[error(
        "vertex {index} has a coordinate of {value} mm, beyond the +-{limit:e} mm within which \
         corners can be welded at {tol} mm (is the mesh in millimetres?)"
    )]
    TooFar {
        /// The vertex.
        index: usize,
        /// The coordinate, mm.
        value: f64,
        /// The largest coordinate magnitude the weld takes, mm.
        limit: f64,
        /// The weld tolerance, mm.
        tol: f64,
    },
    /// The triangles have no area.
    #[error("mesh is degenerate: total area {area} mm^2")]
    Degenerate {
        /// Their total area, mm^2.
        area: f64,
    },
}

impl Mesh {
    /// Build a mesh, check it and compute vertex normals.
    pub fn new(vertices: Vec<Point3<f64>>, triangles: Vec<[u32; 3]>) -> Result<Mesh, MeshError> {
        let mut mesh = Mesh {
            vertices,
            triangles,
            normals: Vec::new(),
        };
        mesh.check()?;
        mesh.recompute_normals();
        Ok(mesh)
    }

    /// What `new` checks, for a mesh whose fields were filled in directly (they are public): at
    /// least three vertices and one triangle, finite coordinates, every triangle's corners among
    /// the vertices, an area.
    pub fn check(&self) -> Result<(), MeshError> {
        let (vertices, triangles) = (&self.vertices, &self.triangles);
        if triangles.is_empty() || vertices.len() < 3 {
            return Err(MeshError::Empty);
        }
        for (index, v) in vertices.iter().enumerate() {
            if let Some(&value) = v.coords.iter().find(|c| !c.is_finite()) {
                return Err(MeshError::NonFinite { index, value });
            }
        }
        self.check_corners()?;
        let area = self.area();
        if !(area > 1e-9) {
            return Err(MeshError::Degenerate { area });
        }
        Ok(())
    }

    /// Every triangle's corners among the vertices (part of `check`; cheap enough for every
    /// call of a function that indexes the vertices by them).
    pub fn check_corners(&self) -> Result<(), MeshError> {
        let n = self.vertices.len();
        for (t, tri) in self.triangles.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(MeshError::IndexOutOfRange {
                    triangle: t,
                    index,
                    vertex_count: n,
                });
            }
        }
        Ok(())
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    /// Recompute area-weighted vertex normals (vertices on no triangle keep a zero normal).
    pub fn recompute_normals(&mut self) {
        let mut n = vec![Vector3::zeros(); self.vertices.len()];
        for tri in &self.triangles {
            let [a, b, c] = tri.map(|i| self.vertices[i as usize]);
            let f = (b - a).cross(&(c - a));
            for &i in tri {
                n[i as usize] += f;
            }
        }
        for v in &mut n {
            let len = v.norm();
            if len > 0.0 {
                *v /= len;
            }
        }
        self.normals = n;
    }

    /// Total surface area in mm^2.
    pub fn area(&self) -> f64 {
        self.triangles
            .iter()
            .map(|tri| {
                let [a, b, c] = tri.map(|i| self.vertices[i as usize]);
                0.5 * (b - a).cross(&(c - a)).norm()
            })
            .sum()
    }

    /// Every triangle side as an undirected edge (i < j), sorted, with repeats.
    fn sorted_sides(&self) -> Vec<[u32; 2]> {
        // Sorted as one u64 per side (i in the high half): the same order as the pairs', with
        // one comparison instead of two.
        let mut e: Vec<u64> = self
            .triangles
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| {
                let (i, j) = if a < b { (a, b) } else { (b, a) };
                (u64::from(i) << 32) | u64::from(j)
            })
            .collect();
        e.sort_unstable();
        e.into_iter()
            .map(|k| [(k >> 32) as u32, k as u32])
            .collect()
    }

    /// Unique undirected edges (i < j).
    pub fn edges(&self) -> Vec<[u32; 2]> {
        let mut e = self.sorted_sides();
        e.dedup();
        e
    }

    /// Mean edge length in mm.
    pub fn mean_edge_length(&self) -> f64 {
        let e = self.edges();
        if e.is_empty() {
            return 0.0;
        }
        e.iter()
            .map(|[a, b]| (self.vertices[*a as usize] - self.vertices[*b as usize]).norm())
            .sum::<f64>()
            / e.len() as f64
    }

    /// Edges used by exactly one triangle (the open border of a surface).
    pub fn boundary_edges(&self) -> Vec<[u32; 2]> {
        let e = self.sorted_sides();
        let mut out = Vec::new();
        let mut i = 0;
        while i < e.len() {
            let mut j = i + 1;
            while j < e.len() && e[j] == e[i] {
                j += 1;
            }
            if j - i == 1 {
                out.push(e[i]);
            }
            i = j;
        }
        out
    }

    /// The triangle counts of the mesh's connected pieces (triangles joined through shared
    /// vertices), largest first.
    pub fn piece_sizes(&self) -> Vec<usize> {
        let mut parent: Vec<usize> = (0..self.vertices.len()).collect();
        fn root(parent: &mut [usize], mut x: usize) -> usize {
            while parent[x] != x {
                parent[x] = parent[parent[x]];
                x = parent[x];
            }
            x
        }
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| i as usize);
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            parent[ra] = rb;
            let (rb, rc) = (root(&mut parent, b), root(&mut parent, c));
            parent[rb] = rc;
        }
        let mut count = std::collections::HashMap::new();
        for t in &self.triangles {
            *count
                .entry(root(&mut parent, t[0] as usize))
                .or_insert(0usize) += 1;
        }
        let mut sizes: Vec<usize> = count.into_values().collect();
        sizes.sort_unstable_by(|a, b| b.cmp(a));
        sizes
    }

    /// This mesh and `other` in one, sharing no vertex (tests: a second piece beside it).
    #[cfg(test)]
    pub(crate) fn joined(&self, other: &Mesh) -> Mesh {
        let n = self.vertices.len() as u32;
        let v = [self.vertices.clone(), other.vertices.clone()].concat();
        let mut t = self.triangles.clone();
        t.extend(other.triangles.iter().map(|f| f.map(|i| i + n)));
        Mesh::new(v, t).expect("two meshes in one")
    }

    /// One triangle on `corners` (tests: a fragment).
    #[cfg(test)]
    pub(crate) fn triangle(corners: [Point3<f64>; 3]) -> Mesh {
        Mesh::new(corners.to_vec(), vec![[0, 1, 2]]).expect("a triangle with an area")
    }

    /// Keep only the listed triangles and the vertices they use (indices are compacted).
    pub fn submesh(&self, keep: &[usize]) -> Result<Mesh, MeshError> {
        let mut map = vec![u32::MAX; self.vertices.len()];
        let mut vertices = Vec::new();
        let mut triangles = Vec::with_capacity(keep.len());
        for &t in keep {
            let tri = self.triangles[t].map(|i| {
                let slot = &mut map[i as usize];
                if *slot == u32::MAX {
                    *slot = vertices.len() as u32;
                    vertices.push(self.vertices[i as usize]);
                }
                *slot
            });
            triangles.push(tri);
        }
        Mesh::new(vertices, triangles)
    }

    /// Weld vertices closer than `tol` mm (STL stores each triangle's corners separately).
    /// Triangles that collapse to an edge or a point are dropped, and so is a triangle on the
    /// same three vertices as an earlier one (either winding: files that list a face twice, or
    /// both sides of it), which would otherwise hide every boundary edge under it.
    /// Coordinates beyond 2^53 tolerances (about 9,000 km at 1e-6 mm) are refused: their keys
    /// would no longer be whole numbers, and past 2^63 every vertex would share one.
    pub fn welded(&self, tol: f64) -> Result<Mesh, MeshError> {
        use std::collections::HashMap;
        let limit = tol * 2f64.powi(53);
        for (index, p) in self.vertices.iter().enumerate() {
            if let Some(&value) = p.coords.iter().find(|c| c.abs() > limit) {
                return Err(MeshError::TooFar {
                    index,
                    value,
                    limit,
                    tol,
                });
            }
        }
        let key = |p: &Point3<f64>| {
            (
                (p.x / tol).round() as i64,
                (p.y / tol).round() as i64,
                (p.z / tol).round() as i64,
            )
        };
        let mut map: HashMap<(i64, i64, i64), u32> = HashMap::new();
        let mut remap = Vec::with_capacity(self.vertices.len());
        let mut vertices = Vec::new();
        for p in &self.vertices {
            let id = *map.entry(key(p)).or_insert_with(|| {
                vertices.push(*p);
                (vertices.len() - 1) as u32
            });
            remap.push(id);
        }
        let mut seen = std::collections::HashSet::new();
        let triangles: Vec<[u32; 3]> = self
            .triangles
            .iter()
            .map(|t| t.map(|i| remap[i as usize]))
            .filter(|t| {
                let mut k = *t;
                k.sort_unstable();
                k[0] != k[1] && k[1] != k[2] && seen.insert(k)
            })
            .collect();
        Mesh::new(vertices, triangles)
    }

    /// Axis-aligned bounding-box diagonal in mm.
    pub fn bbox_diagonal(&self) -> f64 {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for v in &self.vertices {
            lo = lo.inf(&v.coords);
            hi = hi.sup(&v.coords);
        }
        (hi - lo).norm()
    }

    /// Apply `p -> s R p + t` to every vertex and rotate the normals.
    pub fn transformed(&self, s: f64, r: &nalgebra::Rotation3<f64>, t: &Vector3<f64>) -> Mesh {
        let vertices = self
            .vertices
            .iter()
            .map(|p| Point3::from(s * (r * p.coords) + t))
            .collect();
        let normals = self.normals.iter().map(|n| r * n).collect();
        Mesh {
            vertices,
            triangles: self.triangles.clone(),
            normals,
        }
    }

    /// Same topology, new vertex positions; normals recomputed.
    pub fn with_vertices(&self, vertices: Vec<Point3<f64>>) -> Mesh {
        let mut m = Mesh {
            vertices,
            triangles: self.triangles.clone(),
            normals: Vec::new(),
        };
        m.recompute_normals();
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> Mesh {
        let v = vec![
            Point3::new(0.0, 0.0, 0.0),
            Point3::new(1.0, 0.0, 0.0),
            Point3::new(1.0, 1.0, 0.0),
            Point3::new(0.0, 1.0, 0.0),
        ];
        Mesh::new(v, vec![[0, 1, 2], [0, 2, 3]]).unwrap()
    }

    #[test]
    fn area_edges_and_boundary_of_a_unit_square() {
        let m = quad();
        assert!((m.area() - 1.0).abs() < 1e-12);
        assert_eq!(m.edges().len(), 5);
        assert_eq!(m.boundary_edges().len(), 4);
        assert!((m.normals[0] - Vector3::z()).norm() < 1e-12);
    }

    #[test]
    fn bad_meshes_are_rejected_with_the_reason() {
        let v = vec![Point3::origin(); 3];
        assert_eq!(Mesh::new(v.clone(), vec![]), Err(MeshError::Empty));
        assert!(matches!(
            Mesh::new(v.clone(), vec![[0, 1, 7]]),
            Err(MeshError::IndexOutOfRange { index: 7, .. })
        ));
        assert!(matches!(
            Mesh::new(v, vec![[0, 1, 2]]),
            Err(MeshError::Degenerate { .. })
        ));
        let v = vec![
            Point3::new(f64::NAN, 0.0, 0.0),
            Point3::origin(),
            Point3::origin(),
        ];
        assert!(matches!(
            Mesh::new(v, vec![[0, 1, 2]]),
            Err(MeshError::NonFinite { index: 0, .. })
        ));
    }

    #[test]
    fn welding_merges_duplicated_corners() {
        let soup = soup_at(0.0);
        assert_eq!(soup.vertex_count(), 6);
        let w = soup.welded(1e-6).unwrap();
        assert_eq!(w.vertex_count(), 4);
        assert_eq!(w.boundary_edges().len(), 4);
    }

    #[test]
    fn welding_drops_a_face_listed_twice_in_either_winding() {
        let m = quad();
        let mut v = soup_at(0.0).vertices;
        let mut t = soup_at(0.0).triangles;
        // The first face again, as listed, and the second turned over: both sides of it.
        let n = v.len() as u32;
        v.extend(t[0].map(|i| v[i as usize]));
        v.extend([t[1][0], t[1][2], t[1][1]].map(|i| v[i as usize]));
        t.push([n, n + 1, n + 2]);
        t.push([n + 3, n + 4, n + 5]);
        let twice = Mesh::new(v, t).unwrap();
        assert_eq!(twice.triangles.len(), 4);
        let w = twice.welded(1e-6).unwrap();
        assert_eq!(w.triangles.len(), m.triangles.len());
        assert_eq!(w.boundary_edges().len(), 4);
        // Companion: the doubled faces themselves hide the quad's border (each border edge is
        // then shared by two faces), which is what the weld must undo.
        let kept = Mesh::new(
            w.vertices.clone(),
            [w.triangles.clone(), w.triangles.clone()].concat(),
        )
        .unwrap();
        assert!(kept.boundary_edges().is_empty());
    }

    #[test]
    fn pieces_are_counted_through_shared_vertices() {
        let m = quad();
        assert_eq!(m.piece_sizes(), vec![2]);
        // The quad and a triangle apart from it: two pieces.
        let apart = m.joined(&Mesh::triangle([
            Point3::new(5.0, 0.0, 0.0),
            Point3::new(6.0, 0.0, 0.0),
            Point3::new(5.0, 1.0, 0.0),
        ]));
        assert_eq!(apart.piece_sizes(), vec![2, 1]);
        // Companion: the soup's triangles share no vertex until welded.
        assert_eq!(soup_at(0.0).piece_sizes(), vec![1, 1]);
        assert_eq!(soup_at(0.0).welded(1e-6).unwrap().piece_sizes(), vec![2]);
    }

    /// The quad's corners as a triangle soup moved by `shift` mm along x.
    fn soup_at(shift: f64) -> Mesh {
        let m = quad();
        let mut v = Vec::new();
        let mut t = Vec::new();
        for tri in &m.triangles {
            let base = v.len() as u32;
            for &i in tri {
                v.push(m.vertices[i as usize] + Vector3::new(shift, 0.0, 0.0));
            }
            t.push([base, base + 1, base + 2]);
        }
        Mesh::new(v, t).unwrap()
    }

    #[test]
    fn a_mesh_far_out_is_refused_by_the_weld_not_collapsed() {
        // 1e12 mm: past 2^53 tolerances the keys are no longer whole numbers (and past 2^63,
        // as with a file's 1e30, every key saturates to one and no triangle is left).
        let far = soup_at(1e12).welded(1e-6);
        assert!(
            matches!(far, Err(MeshError::TooFar { index: 0, .. })),
            "{far:?}"
        );
        // Companion: the same soup a kilometre out still welds to the quad.
        let near = soup_at(1e6).welded(1e-6).unwrap();
        assert_eq!(near.vertex_count(), 4);
    }
}
