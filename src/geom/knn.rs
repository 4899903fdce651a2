//! k-nearest-neighbour queries over 3D points (kiddo's immutable k-d tree).

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;
use std::num::NonZero;

/// A k-d tree over a fixed set of 3D points.
pub struct Knn3 {
    tree: Option<ImmutableKdTree<f64, 3>>,
    len: usize,
}

impl Knn3 {
    /// A k-d tree over the points (kiddo).
    pub fn new(points: &[Point3<f64>]) -> Knn3 {
        let entries: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        let tree = if entries.is_empty() {
            None
        } else {
            ImmutableKdTree::new_from_slice(&entries).ok()
        };
        Knn3 {
            tree,
            len: entries.len(),
        }
    }

    /// The `k` nearest points as (index, distance), nearest first (fewer if the set is smaller).
    pub fn nearest(&self, q: &Point3<f64>, k: usize) -> Vec<(usize, f64)> {
        let (Some(tree), Some(k)) = (&self.tree, NonZero::new(k.min(self.len))) else {
            return Vec::new();
        };
        tree.query(&[q.x, q.y, q.z])
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .into_iter()
            .map(|r| (r.item as usize, r.distance.max(0.0).sqrt()))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_points_come_in_order() {
        let pts: Vec<Point3<f64>> = (0..10).map(|i| Point3::new(i as f64, 0.0, 0.0)).collect();
        let knn = Knn3::new(&pts);
        let r = knn.nearest(&Point3::new(3.2, 0.0, 0.0), 3);
        assert_eq!(r.iter().map(|x| x.0).collect::<Vec<_>>(), vec![3, 4, 2]);
        assert!((r[0].1 - 0.2).abs() < 1e-12);
        assert_eq!(knn.nearest(&Point3::origin(), 50).len(), 10);
        assert!(Knn3::new(&[]).nearest(&Point3::origin(), 3).is_empty());
    }
}
