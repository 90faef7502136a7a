//! Shared helpers of the view-factor tests: the reference cases and their geometry.
#![allow(dead_code)]

use std::f64::consts::PI;

use glam::DVec3;
use radiosity::scene::{MaterialDesc, ObjectDesc, PolygonDesc, Scene, SceneDesc};
use radiosity::Rgb;

pub const DATA: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data");

/// One row of the reference CSVs: the geometry and the value.
#[derive(Clone, Debug)]
pub struct Case {
    pub label: String,
    pub kind: Kind,
    /// The value as printed in the CSV (9–12 significant digits).
    pub csv: f64,
}

#[derive(Clone, Copy, Debug)]
pub enum Kind {
    /// Howell C-11: a × b rectangles directly opposed at distance c.
    Parallel { a: f64, b: f64, c: f64 },
    /// Howell C-14: from the rectangle of width h to the one of width w, common edge l.
    Perpendicular { w: f64, h: f64, l: f64 },
    /// Howell C-41: coaxial disks r1 → r2 at distance h.
    Disks { r1: f64, r2: f64, h: f64 },
}

/// Splits a CSV line on commas outside double quotes.
fn split_csv(line: &str) -> Vec<String> {
    let mut out = vec![String::new()];
    let mut quoted = false;
    for ch in line.chars() {
        match ch {
            '"' => quoted = !quoted,
            ',' if !quoted => out.push(String::new()),
            c => out.last_mut().unwrap().push(c),
        }
    }
    out
}

fn params(s: &str) -> std::collections::HashMap<String, f64> {
    s.split(';')
        .map(|kv| {
            let (k, v) = kv.split_once('=').unwrap();
            (k.trim().to_string(), v.trim().parse().unwrap())
        })
        .collect()
}

/// Every case of analytic_view_factors.csv and the disks of analytic_view_factors_extra.csv.
pub fn cases() -> Vec<Case> {
    let mut out = Vec::new();
    let text = std::fs::read_to_string(format!("{DATA}/analytic_view_factors.csv")).unwrap();
    for line in text.lines().filter(|l| !l.starts_with('#') && !l.starts_with("case,")) {
        let f = split_csv(line);
        let p = params(&f[1]);
        let kind = if f[0].starts_with("parallel_rect") {
            Kind::Parallel { a: p["a"], b: p["b"], c: p["c"] }
        } else if f[0].starts_with("perpendicular_rect") {
            Kind::Perpendicular { w: p["w"], h: p["h"], l: p["l"] }
        } else {
            panic!("unknown case {}", f[0])
        };
        out.push(Case { label: format!("{} {}", &f[0][..f[0].find(' ').unwrap()], f[1]), kind, csv: f[2].parse().unwrap() });
    }
    let text = std::fs::read_to_string(format!("{DATA}/analytic_view_factors_extra.csv")).unwrap();
    for line in text.lines().skip(1) {
        let f = split_csv(line);
        let (r1, r2, h) = (f[2].parse().unwrap(), f[3].parse().unwrap(), f[4].parse().unwrap());
        out.push(Case {
            label: format!("disks r1={r1} r2={r2} h={h}"),
            kind: Kind::Disks { r1, r2, h },
            csv: f[5].parse().unwrap(),
        });
    }
    assert_eq!(out.len(), 16);
    out
}

impl Kind {
    /// The closed form, evaluated in f64 (Howell's catalogue).
    pub fn exact(self) -> f64 {
        match self {
            Kind::Parallel { a, b, c } => {
                let (x, y) = (a / c, b / c);
                let (x2, y2) = (x * x, y * y);
                2.0 / (PI * x * y)
                    * ((((1.0 + x2) * (1.0 + y2)) / (1.0 + x2 + y2)).sqrt().ln()
                        + x * (1.0 + y2).sqrt() * (x / (1.0 + y2).sqrt()).atan()
                        + y * (1.0 + x2).sqrt() * (y / (1.0 + x2).sqrt()).atan()
                        - x * x.atan()
                        - y * y.atan())
            }
            Kind::Perpendicular { w, h, l } => {
                // Howell C-14 with H = h/l, W = w/l, from the surface of width h.
                let (hh, ww) = (h / l, w / l);
                let (h2, w2) = (hh * hh, ww * ww);
                let s = (h2 + w2).sqrt();
                let a = (1.0 + w2) * (1.0 + h2) / (1.0 + w2 + h2);
                let b = w2 * (1.0 + w2 + h2) / ((1.0 + w2) * (w2 + h2));
                let c = h2 * (1.0 + h2 + w2) / ((1.0 + h2) * (h2 + w2));
                1.0 / (PI * hh)
                    * (hh * (1.0 / hh).atan() + ww * (1.0 / ww).atan() - s * (1.0 / s).atan()
                        + 0.25 * (a.ln() + w2 * b.ln() + h2 * c.ln()))
            }
            Kind::Disks { r1, r2, h } => {
                let (a, b) = (r1 / h, r2 / h);
                let x = 1.0 + (1.0 + b * b) / (a * a);
                0.5 * (x - (x * x - 4.0 * (b / a).powi(2)).sqrt())
            }
        }
    }

    /// The two surfaces as a scene: object 0 ("from") sends, object 1 ("to") receives,
    /// fronts facing each other.
    pub fn scene(self) -> Scene {
        let v = DVec3::new;
        let (from, to): (Vec<DVec3>, Vec<DVec3>) = match self {
            Kind::Parallel { a, b, c } => (
                vec![v(0., 0., 0.), v(a, 0., 0.), v(a, b, 0.), v(0., b, 0.)],
                vec![v(0., 0., c), v(0., b, c), v(a, b, c), v(a, 0., c)],
            ),
            Kind::Perpendicular { w, h, l } => (
                // Width h in the plane z = 0 (front +z); width w in y = 0 (front +y).
                vec![v(0., 0., 0.), v(l, 0., 0.), v(l, h, 0.), v(0., h, 0.)],
                vec![v(0., 0., 0.), v(0., 0., w), v(l, 0., w), v(l, 0., 0.)],
            ),
            Kind::Disks { r1, r2, h } => {
                let n = 256;
                // Equal area: (n/2) R² sin(2π/n) = π r².
                let k = (2.0 * PI / n as f64 / (2.0 * PI / n as f64).sin()).sqrt();
                let ring = |r: f64, z: f64, ccw: bool| -> Vec<DVec3> {
                    (0..n)
                        .map(|i| {
                            let t = 2.0 * PI * i as f64 / n as f64 * if ccw { 1.0 } else { -1.0 };
                            v(r * k * t.cos(), r * k * t.sin(), z)
                        })
                        .collect()
                };
                (ring(r1, 0.0, true), ring(r2, h, false))
            }
        };
        two_surfaces(from, to)
    }
}

/// A scene of two one-sided polygons named "from" and "to".
pub fn two_surfaces(from: Vec<DVec3>, to: Vec<DVec3>) -> Scene {
    let desc = SceneDesc {
        name: "case".into(),
        materials: vec![MaterialDesc::diffuse("grey", Rgb::splat(0.5))],
        objects: vec![ObjectDesc { name: "from".into(), loc: None }, ObjectDesc { name: "to".into(), loc: None }],
        polygons: vec![
            PolygonDesc { uvs: Vec::new(), vertices: from, material: 0, object: 0, loc: None },
            PolygonDesc { uvs: Vec::new(), vertices: to, material: 0, object: 1, loc: None },
        ],
        ..Default::default()
    };
    Scene::from_desc(desc).unwrap()
}

/// The closed unit cube, faces inwards, one object per face (the furnace's geometry).
pub fn unit_cube() -> Scene {
    Scene::from_desc(radiosity::scene::builtin::furnace(0.5, 0.0)).unwrap()
}

impl Kind {
    /// As [`Kind::scene`], but each disk's 256-gon is cut into `rings` annuli of equal area
    /// (256 quads each, triangles in the middle): the same surface, tessellated so that the
    /// element methods get compact elements instead of the polygon's long fan slivers.
    pub fn scene_rings(self, rings: usize) -> Scene {
        let Kind::Disks { r1, r2, h } = self else { return self.scene() };
        let n = 256;
        let k = (2.0 * PI / n as f64 / (2.0 * PI / n as f64).sin()).sqrt();
        let disk = |r: f64, z: f64, up: bool| -> Vec<Vec<DVec3>> {
            let pt = |rho: f64, i: usize| {
                let t = 2.0 * PI * (i % n) as f64 / n as f64;
                DVec3::new(rho * t.cos(), rho * t.sin(), z)
            };
            let rad = |m: usize| r * k * (m as f64 / rings as f64).sqrt();
            let mut polys = Vec::new();
            for i in 0..n {
                polys.push(vec![DVec3::new(0.0, 0.0, z), pt(rad(1), i), pt(rad(1), i + 1)]);
                for m in 1..rings {
                    polys.push(vec![pt(rad(m), i), pt(rad(m + 1), i), pt(rad(m + 1), i + 1), pt(rad(m), i + 1)]);
                }
            }
            for p in polys.iter_mut() {
                let nz = radiosity::scene::newell_normal(p).z;
                if (nz > 0.0) != up {
                    p.reverse();
                }
            }
            polys
        };
        let mut desc = SceneDesc {
            name: "rings".into(),
            materials: vec![MaterialDesc::diffuse("grey", Rgb::splat(0.5))],
            objects: vec![ObjectDesc { name: "from".into(), loc: None }, ObjectDesc { name: "to".into(), loc: None }],
            ..Default::default()
        };
        for (o, polys) in [(0u32, disk(r1, 0.0, true)), (1, disk(r2, h, false))] {
            for v in polys {
                desc.polygons.push(PolygonDesc { uvs: Vec::new(), vertices: v, material: 0, object: o, loc: None });
            }
        }
        Scene::from_desc(desc).unwrap()
    }
}
