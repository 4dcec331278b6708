//! Planar geometry of footprints: oriented rectangles on the floor plane. Cylinders are treated as
//! their square bounding footprint, which is conservative for every check made here.

/// An oriented rectangle: centre, half extents along its own x/y axes, yaw about +z.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rect {
    pub centre: [f64; 2],
    pub half: [f64; 2],
    pub yaw: f64,
}

impl Rect {
    pub fn new(centre: [f64; 2], size: [f64; 2], yaw: f64) -> Self {
        Self {
            centre,
            half: [size[0] * 0.5, size[1] * 0.5],
            yaw,
        }
    }

    fn axes(&self) -> [[f64; 2]; 2] {
        let (s, c) = self.yaw.sin_cos();
        [[c, s], [-s, c]]
    }

    /// World point to the rectangle's frame.
    pub fn to_local(&self, p: [f64; 2]) -> [f64; 2] {
        let d = [p[0] - self.centre[0], p[1] - self.centre[1]];
        let [ax, ay] = self.axes();
        [dot(d, ax), dot(d, ay)]
    }

    /// Rectangle-frame point to the world.
    pub fn to_world(&self, l: [f64; 2]) -> [f64; 2] {
        let [ax, ay] = self.axes();
        [
            self.centre[0] + l[0] * ax[0] + l[1] * ay[0],
            self.centre[1] + l[0] * ax[1] + l[1] * ay[1],
        ]
    }

    pub fn corners(&self) -> [[f64; 2]; 4] {
        let [hx, hy] = self.half;
        [
            self.to_world([-hx, -hy]),
            self.to_world([hx, -hy]),
            self.to_world([hx, hy]),
            self.to_world([-hx, hy]),
        ]
    }

    /// Euclidean distance from a point to the rectangle (0 inside).
    pub fn distance(&self, p: [f64; 2]) -> f64 {
        let l = self.to_local(p);
        let dx = (l[0].abs() - self.half[0]).max(0.0);
        let dy = (l[1].abs() - self.half[1]).max(0.0);
        (dx * dx + dy * dy).sqrt()
    }

    /// Whether `p` lies inside the rectangle shrunk by `margin` on every side.
    pub fn contains_point(&self, p: [f64; 2], margin: f64) -> bool {
        let l = self.to_local(p);
        l[0].abs() <= self.half[0] - margin && l[1].abs() <= self.half[1] - margin
    }

    /// Whether `inner` lies entirely inside this rectangle shrunk by `margin`.
    pub fn contains_rect(&self, inner: &Rect, margin: f64) -> bool {
        inner
            .corners()
            .iter()
            .all(|&c| self.contains_point(c, margin - 1e-9))
    }

    /// Separating-axis test: true when the two rectangles come closer than `gap` along every
    /// candidate axis (i.e. they overlap once each is grown by `gap / 2`; corners are treated as
    /// square, which errs on the side of reporting an overlap).
    pub fn overlaps(&self, other: &Rect, gap: f64) -> bool {
        let axes = [
            self.axes()[0],
            self.axes()[1],
            other.axes()[0],
            other.axes()[1],
        ];
        axes.iter().all(|&axis| {
            let (a0, a1) = self.project(axis);
            let (b0, b1) = other.project(axis);
            let separation = (b0 - a1).max(a0 - b1);
            separation < gap
        })
    }

    fn project(&self, axis: [f64; 2]) -> (f64, f64) {
        let c = dot(self.centre, axis);
        let [ax, ay] = self.axes();
        let r = self.half[0] * dot(ax, axis).abs() + self.half[1] * dot(ay, axis).abs();
        (c - r, c + r)
    }
}

pub fn dot(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

pub fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)).sqrt()
}

/// The room's floor as a rectangle centred on the origin.
pub fn room_rect(room_size: [f64; 2]) -> Rect {
    Rect::new([0.0, 0.0], room_size, 0.0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_4;

    #[test]
    fn distance_and_containment() {
        let r = Rect::new([1.0, 0.0], [2.0, 1.0], 0.0);
        assert_eq!(r.distance([1.0, 0.0]), 0.0);
        assert!((r.distance([3.0, 0.0]) - 1.0).abs() < 1e-12);
        assert!((r.distance([3.0, 1.5]) - 2f64.sqrt()).abs() < 1e-12);
        assert!(r.contains_point([1.9, 0.4], 0.05));
        assert!(!r.contains_point([1.9, 0.4], 0.2));
        let rotated = Rect::new([0.0, 0.0], [2.0, 2.0], FRAC_PI_4);
        // The corner of the rotated square points along +x at sqrt(2).
        assert!(rotated.contains_point([1.4, 0.0], 0.0));
        assert!(!rotated.contains_point([1.0, 1.0], 0.0));
    }

    #[test]
    fn overlap_uses_rotated_axes() {
        let a = Rect::new([0.0, 0.0], [1.0, 1.0], 0.0);
        // Touching along x with a 0.1 gap: overlapping only when the required gap exceeds it.
        let b = Rect::new([1.1, 0.0], [1.0, 1.0], 0.0);
        assert!(!a.overlaps(&b, 0.0));
        assert!(a.overlaps(&b, 0.2));
        // A diamond whose corner stops short of the square's corner region: the square's axes
        // alone would call it overlapping, the diamond's axes separate them.
        let d = Rect::new([1.2, 1.2], [1.0, 1.0], FRAC_PI_4);
        assert!(!a.overlaps(&d, 0.0));
        let e = Rect::new([0.8, 0.8], [1.0, 1.0], FRAC_PI_4);
        assert!(a.overlaps(&e, 0.0));
    }

    #[test]
    fn contains_rect_respects_rotation() {
        let top = Rect::new([0.0, 0.0], [1.2, 0.6], 0.3);
        let small = Rect::new(top.to_world([0.2, 0.0]), [0.3, 0.2], 0.3);
        assert!(top.contains_rect(&small, 0.02));
        let sideways = Rect::new(
            top.to_world([0.2, 0.0]),
            [0.3, 0.2],
            0.3 + std::f64::consts::FRAC_PI_2,
        );
        assert!(top.contains_rect(&sideways, 0.02));
        let off = Rect::new(top.to_world([0.5, 0.0]), [0.3, 0.2], 0.3);
        assert!(!top.contains_rect(&off, 0.0));
    }
}
