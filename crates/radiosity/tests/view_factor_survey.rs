//! Not a test: prints every method's error on every reference case (run with --ignored).
mod vf_common;

use radiosity::form_factor::{Method, Options};
use radiosity::view_factors::{compute, Per, Settings};
use radiosity::NoProgress;

#[test]
#[ignore]
fn survey() {
    let size: Option<f64> = std::env::var("SURVEY_MESH").ok().map(|s| s.parse().unwrap());
    let methods: Vec<Method> = match std::env::var("SURVEY_METHODS") {
        Ok(s) => s.split(',').map(|m| m.parse().unwrap()).collect(),
        Err(_) => Method::ALL.to_vec(),
    };
    for m in methods {
        let mut worst: f64 = 0.0;
        let t = std::time::Instant::now();
        for c in vf_common::cases().into_iter().filter(|c| std::env::var("SURVEY_ONLY").map_or(true, |o| c.label.contains(&o))) {
            let exact = c.kind.exact();
            let st = Settings {
                per: Per::Object,
                mesh_size: if let vf_common::Kind::Disks { r1, r2, .. } = c.kind { Some(std::env::var("SURVEY_DISK_K").map_or(0.0, |k| 2.0 * r1.max(r2) / k.parse::<f64>().unwrap())) } else { size.map(|s| s * c.kind.scene().diagonal()) },
                form_factors: Options { method: m, hemicube_resolution: std::env::var("SURVEY_RES").map_or(radiosity::form_factor::hemicube::DEFAULT_RESOLUTION, |r| r.parse().unwrap()), ..Default::default() },
                enclosure: false,
            };
            let t1 = std::time::Instant::now();
            let vf = compute(c.kind.scene(), &st, &NoProgress).unwrap();
            let f = vf.matrix.get(0, 1);
            let rel = (f - exact) / exact;
            worst = worst.max(rel.abs());
            println!("{:13} {:45} F={f:.12} exact={exact:.12} csv={:.12} rel={rel:+.3e} elems={} {:.2}s", m.name(), c.label, c.csv, vf.elements, t1.elapsed().as_secs_f64());
        }
        println!("{:13} worst {worst:.3e} total {:.1}s", m.name(), t.elapsed().as_secs_f64());
    }
}

