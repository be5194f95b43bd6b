//! Plane geometry on the floor (x–z) plane, in metres.

use serde::{Deserialize, Serialize};

/// A point on the floor plane, metres. ProcTHOR's `x` and `z`; height (`y`) is dropped.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// Metres along the world x axis.
    pub x: f64,
    /// Metres along the world z axis.
    pub z: f64,
}

impl Point {
    /// A point at `(x, z)`.
    pub const fn new(x: f64, z: f64) -> Self {
        Self { x, z }
    }

    /// Straight-line distance in metres.
    pub fn distance(self, other: Point) -> f64 {
        (self.x - other.x).hypot(self.z - other.z)
    }

    /// True when both coordinates are finite.
    pub fn is_finite(self) -> bool {
        self.x.is_finite() && self.z.is_finite()
    }
}

/// An axis-aligned rectangle.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Rect {
    /// Smallest x and z.
    pub min: Point,
    /// Largest x and z.
    pub max: Point,
}

impl Rect {
    /// The smallest rectangle holding every point; `None` for no points.
    pub fn around(points: impl IntoIterator<Item = Point>) -> Option<Rect> {
        let mut it = points.into_iter();
        let first = it.next()?;
        let mut r = Rect {
            min: first,
            max: first,
        };
        for p in it {
            r.min.x = r.min.x.min(p.x);
            r.min.z = r.min.z.min(p.z);
            r.max.x = r.max.x.max(p.x);
            r.max.z = r.max.z.max(p.z);
        }
        Some(r)
    }

    /// Width along x, metres.
    pub fn width(&self) -> f64 {
        self.max.x - self.min.x
    }

    /// Depth along z, metres.
    pub fn depth(&self) -> f64 {
        self.max.z - self.min.z
    }

    /// The union of two rectangles.
    pub fn union(&self, other: &Rect) -> Rect {
        Rect {
            min: Point::new(self.min.x.min(other.min.x), self.min.z.min(other.min.z)),
            max: Point::new(self.max.x.max(other.max.x), self.max.z.max(other.max.z)),
        }
    }
}

/// A simple polygon (no self-intersections assumed), vertices in order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Polygon {
    /// The vertices, in order; the last connects back to the first.
    pub vertices: Vec<Point>,
}

impl Polygon {
    /// A polygon from its vertices.
    pub fn new(vertices: Vec<Point>) -> Self {
        Self { vertices }
    }

    /// Area in square metres (shoelace formula; orientation ignored).
    pub fn area(&self) -> f64 {
        let v = &self.vertices;
        let n = v.len();
        if n < 3 {
            return 0.0;
        }
        let twice: f64 = (0..n)
            .map(|i| {
                let (a, b) = (v[i], v[(i + 1) % n]);
                a.x * b.z - b.x * a.z
            })
            .sum();
        twice.abs() / 2.0
    }

    /// Even-odd point-in-polygon test; points exactly on an edge may go either way.
    pub fn contains(&self, p: Point) -> bool {
        let v = &self.vertices;
        let n = v.len();
        let mut inside = false;
        let mut j = n.wrapping_sub(1);
        for i in 0..n {
            let (a, b) = (v[i], v[j]);
            if (a.z > p.z) != (b.z > p.z) {
                let x_cross = (b.x - a.x) * (p.z - a.z) / (b.z - a.z) + a.x;
                if p.x < x_cross {
                    inside = !inside;
                }
            }
            j = i;
        }
        inside
    }

    /// The bounding rectangle; `None` for an empty polygon.
    pub fn bounds(&self) -> Option<Rect> {
        Rect::around(self.vertices.iter().copied())
    }

    /// Distance from `p` to the polygon's outline, metres.
    pub fn distance_to_edge(&self, p: Point) -> f64 {
        self.edges()
            .map(|(a, b)| segment_distance(a, b, p))
            .fold(f64::INFINITY, f64::min)
    }

    /// The edges, each from a vertex to the next.
    pub fn edges(&self) -> impl Iterator<Item = (Point, Point)> + '_ {
        let v = &self.vertices;
        (0..v.len()).map(move |i| (v[i], v[(i + 1) % v.len()]))
    }

    /// True when the two polygons share floor deeper than `tolerance` metres: some point lies
    /// inside both, farther than `tolerance` from either outline. Polygons that only share (parts
    /// of) edges or corners do not overlap.
    ///
    /// The shared region, if any, is bounded by pieces of the two outlines; every edge is cut
    /// where the other outline touches or crosses it, and points just off the middle of each
    /// piece, on both sides, are tried.
    pub fn overlaps(&self, other: &Polygon, tolerance: f64) -> bool {
        let (Some(a), Some(b)) = (self.bounds(), other.bounds()) else {
            return false;
        };
        if a.min.x >= b.max.x - tolerance
            || b.min.x >= a.max.x - tolerance
            || a.min.z >= b.max.z - tolerance
            || b.min.z >= a.max.z - tolerance
        {
            return false;
        }
        let deep =
            |poly: &Polygon, p: Point| poly.contains(p) && poly.distance_to_edge(p) > tolerance;
        let offset = 2.0 * tolerance;
        let tries = |outline: &Polygon, cutter: &Polygon| {
            outline.edges().any(|(p, q)| {
                let len = p.distance(q);
                if len <= 0.0 {
                    return false;
                }
                let mut cuts = vec![0.0, 1.0];
                for (r, s) in cutter.edges() {
                    cuts.extend(crossing(p, q, r, s));
                    for v in [r, s] {
                        if segment_distance(p, q, v) <= tolerance {
                            let t = ((v.x - p.x) * (q.x - p.x) + (v.z - p.z) * (q.z - p.z))
                                / (len * len);
                            cuts.push(t.clamp(0.0, 1.0));
                        }
                    }
                }
                cuts.sort_by(f64::total_cmp);
                let (nx, nz) = (-(q.z - p.z) / len, (q.x - p.x) / len);
                cuts.windows(2).any(|w| {
                    let t = (w[0] + w[1]) / 2.0;
                    let m = Point::new(p.x + t * (q.x - p.x), p.z + t * (q.z - p.z));
                    [1.0, -1.0].into_iter().any(|side: f64| {
                        let c = Point::new(m.x + side * offset * nx, m.z + side * offset * nz);
                        deep(self, c) && deep(other, c)
                    })
                })
            })
        };
        tries(self, other) || tries(other, self)
    }

    /// The vertex average, a label position good enough for convex-ish rooms.
    pub fn centroid(&self) -> Point {
        let n = self.vertices.len().max(1) as f64;
        let (sx, sz) = self
            .vertices
            .iter()
            .fold((0.0, 0.0), |(sx, sz), p| (sx + p.x, sz + p.z));
        Point::new(sx / n, sz / n)
    }
}

/// The floor footprint of a piece of furniture: a rectangle rotated about its centre.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Footprint {
    /// Centre on the floor, metres.
    pub center: Point,
    /// Size along the object's own x axis, metres.
    pub size_x: f64,
    /// Size along the object's own z axis, metres.
    pub size_z: f64,
    /// Rotation about the vertical axis, degrees, as ProcTHOR's `rotation.y`.
    pub yaw_deg: f64,
}

impl Footprint {
    /// The four corners in world coordinates.
    ///
    /// Unity rotates clockwise seen from above for positive yaw about +y (left-handed axes), so a
    /// local offset (dx, dz) lands at (dx·cos + dz·sin, −dx·sin + dz·cos).
    pub fn corners(&self) -> [Point; 4] {
        let (s, c) = self.yaw_deg.to_radians().sin_cos();
        let (hx, hz) = (self.size_x / 2.0, self.size_z / 2.0);
        [(-hx, -hz), (hx, -hz), (hx, hz), (-hx, hz)].map(|(dx, dz)| {
            Point::new(
                self.center.x + dx * c + dz * s,
                self.center.z - dx * s + dz * c,
            )
        })
    }

    /// The footprint as a polygon.
    pub fn polygon(&self) -> Polygon {
        Polygon::new(self.corners().to_vec())
    }

    /// True when `p` lies inside the rotated rectangle.
    pub fn contains(&self, p: Point) -> bool {
        let (s, c) = self.yaw_deg.to_radians().sin_cos();
        let (dx, dz) = (p.x - self.center.x, p.z - self.center.z);
        // Inverse of the rotation in `corners`.
        let lx = dx * c - dz * s;
        let lz = dx * s + dz * c;
        lx.abs() <= self.size_x / 2.0 && lz.abs() <= self.size_z / 2.0
    }
}

/// Distance from `p` to segment `a`–`b`, metres.
pub fn segment_distance(a: Point, b: Point, p: Point) -> f64 {
    let (dx, dz) = (b.x - a.x, b.z - a.z);
    let len2 = dx * dx + dz * dz;
    if len2 <= 0.0 {
        return a.distance(p);
    }
    let t = (((p.x - a.x) * dx + (p.z - a.z) * dz) / len2).clamp(0.0, 1.0);
    Point::new(a.x + t * dx, a.z + t * dz).distance(p)
}

/// Where segment `r`–`s` crosses segment `p`–`q`, as a fraction of the way from `p` to `q`;
/// `None` for parallel segments or segments that do not meet.
fn crossing(p: Point, q: Point, r: Point, s: Point) -> Option<f64> {
    let (dx, dz) = (q.x - p.x, q.z - p.z);
    let (ex, ez) = (s.x - r.x, s.z - r.z);
    let denom = dx * ez - dz * ex;
    if denom.abs() < 1e-12 {
        return None;
    }
    let t = ((r.x - p.x) * ez - (r.z - p.z) * ex) / denom;
    let u = ((r.x - p.x) * dz - (r.z - p.z) * dx) / denom;
    ((0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn l_shaped_room_area_and_containment() {
        // The bedroom of the first multiroom house, an L shape.
        let poly = Polygon::new(vec![
            Point::new(5.025, 6.7),
            Point::new(5.025, 11.724),
            Point::new(10.049, 11.724),
            Point::new(10.049, 0.0),
            Point::new(8.375, 0.0),
            Point::new(8.375, 6.7),
        ]);
        let expected = 5.024 * 5.024 + 1.674 * 6.7;
        assert!((poly.area() - expected).abs() < 1e-9);
        assert!(poly.contains(Point::new(9.0, 1.0)));
        assert!(poly.contains(Point::new(6.0, 10.0)));
        assert!(!poly.contains(Point::new(6.0, 1.0)));
    }

    #[test]
    fn rotated_footprint_corners_are_inside_and_contain_matches() {
        let f = Footprint {
            center: Point::new(1.0, 2.0),
            size_x: 2.0,
            size_z: 0.5,
            yaw_deg: 90.0,
        };
        // A 90° turn swaps the extents: long along z.
        let r = Rect::around(f.corners()).unwrap();
        assert!((r.width() - 0.5).abs() < 1e-9, "{r:?}");
        assert!((r.depth() - 2.0).abs() < 1e-9, "{r:?}");
        assert!(f.contains(Point::new(1.0, 2.9)));
        assert!(!f.contains(Point::new(1.9, 2.0)));
    }
}
