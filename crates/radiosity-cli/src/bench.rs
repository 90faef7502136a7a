//! `radiosity bench rays`: ray-casting throughput of our BVH ([`radiosity::accel::Bvh`]) on
//! incoherent rays and — in a build with `--features embree` — of Embree on the very same
//! rays in the same invocation, so that the ratio means something on a noisy shared machine.
//!
//! Two fixed, seeded ray sets per scene, from area-weighted uniform points on the scene's
//! triangles: closest-hit rays leaving a surface point in a cosine-weighted direction about
//! its normal (gathering), and segments between two random surface points traced as any-hit
//! queries (form-factor visibility, as `SceneRays::visible` casts them). Each set is traced
//! `--runs` times, alternating backends run by run, and the medians are reported. The
//! visibility path the solver really uses (any-hit with the two end polygons filtered out)
//! is timed too, for our BVH only: Embree would need a filter callback for it.

use std::path::Path;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use clap::{Args, Subcommand};
use radiosity::accel::{Bvh, Ray, SceneRays};
use radiosity::accel::workload::{make_rays, triangles};
use rayon::prelude::*;

/// Flags of `radiosity bench`.
#[derive(Args, Debug)]
pub struct BenchArgs {
    #[command(subcommand)]
    pub what: BenchWhat,
}

/// What to benchmark.
#[derive(Subcommand, Debug)]
pub enum BenchWhat {
    /// Closest-hit and any-hit rays per second on incoherent rays (and Embree's, when the
    /// program is built with `--features embree`).
    Rays(RaysArgs),
}

/// Flags of `radiosity bench rays`.
#[derive(Args, Debug)]
pub struct RaysArgs {
    /// Scenes: built-in names or files [default: cornell and, when present,
    /// ../shared/scenes/sponza-dabrovic/sponza.obj and ../shared/scenes/conference/conference.obj].
    pub scenes: Vec<String>,
    /// Rays per set (closest-hit and any-hit each).
    #[arg(long, value_name = "N", default_value_t = 1_000_000)]
    pub rays: usize,
    /// Threads tracing (and building).
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub threads: usize,
    /// Timed runs per measurement; the median is reported.
    #[arg(long, value_name = "N", default_value_t = 5)]
    pub runs: usize,
    /// Seed of the ray sets.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Also race Embree's 8-ray packets (rtcIntersect8 / rtcOccluded8) on the same rays,
    /// eight consecutive rays per packet (with --features embree).
    #[arg(long)]
    pub packets: bool,
    /// Extra Embree device configuration appended to `threads=N`, e.g. `isa=avx2` or
    /// `verbose=1` (with --features embree).
    #[arg(long, value_name = "CONFIG", default_value = "")]
    pub embree_config: String,
}

const DEFAULT_SCENES: [&str; 3] = [
    "cornell",
    "../shared/scenes/sponza-dabrovic/sponza.obj",
    "../shared/scenes/conference/conference.obj",
];

/// Rays handed to a pool thread at a time.
const CHUNK: usize = 1024;

pub fn run(a: BenchArgs) -> Result<ExitCode> {
    match a.what {
        BenchWhat::Rays(r) => rays(r),
    }
}

fn rays(a: RaysArgs) -> Result<ExitCode> {
    anyhow::ensure!(a.rays > 0 && a.runs > 0, "--rays and --runs must be positive");
    crate::common::check_threads(Some(a.threads))?;
    let pool = rayon::ThreadPoolBuilder::new().num_threads(a.threads).build()?;
    let scenes: Vec<String> =
        if a.scenes.is_empty() { DEFAULT_SCENES.iter().map(|s| s.to_string()).collect() } else { a.scenes.clone() };
    println!(
        "bench rays: {} rays per set, {} thread(s), median of {} runs, seed {}; machine: {} ({} cores)",
        a.rays,
        a.threads,
        a.runs,
        a.seed,
        cpu_model(),
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    if cfg!(not(feature = "embree")) {
        println!("(built without --features embree: our BVH only)");
    }
    for spec in &scenes {
        let path = Path::new(spec);
        if path.extension().is_some() && !path.exists() {
            println!("\nscene {spec}: file not found, skipped");
            continue;
        }
        let scene = radiosity::scene::load_scene(spec).with_context(|| format!("loading {spec}"))?;
        bench_scene(spec, &scene, &a, &pool)?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Slices each timed run is cut into; backends alternate slice by slice.
const SLICES: usize = 32;

/// A query run by one backend: ray index and ray to result.
type Query<'a, T> = &'a (dyn Fn(usize, &Ray) -> T + Sync);

/// CPU time consumed by the calling thread, in seconds (Linux/Unix; 0 elsewhere).
fn thread_cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
        // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
        if unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) } == 0 {
            return ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9;
        }
    }
    0.0
}

/// CPU time consumed by the whole process (all threads), in seconds (Unix; 0 elsewhere).
fn process_cpu_seconds() -> f64 {
    #[cfg(unix)]
    {
        // SAFETY: an all-zero `rusage` is a valid value; getrusage writes into it.
        let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
        // SAFETY: `ru` is valid and writable for the duration of the call.
        if unsafe { libc::getrusage(libc::RUSAGE_SELF, &mut ru) } == 0 {
            let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
            return tv(ru.ru_utime) + tv(ru.ru_stime);
        }
    }
    0.0
}

/// Seconds one backend took: wall clock, and CPU time summed over the tracing threads
/// (which leaves out the time slices other processes got on a shared machine).
#[derive(Clone, Copy, Default)]
struct Secs {
    wall: f64,
    cpu: f64,
}

/// Traces every ray once with each backend, alternating between backends slice by slice
/// (and which goes first), so that load from other processes falls on all of them alike;
/// returns the time each took. `outs[b]` receives backend `b`'s results.
fn race<T: Send>(pool: &rayon::ThreadPool, rays: &[Ray], outs: &mut [Vec<T>], backends: &[Query<T>]) -> Vec<Secs> {
    let mut secs = vec![Secs::default(); backends.len()];
    let slice = rays.len().div_ceil(SLICES).max(CHUNK);
    for (s, start) in (0..rays.len()).step_by(slice).enumerate() {
        let end = (start + slice).min(rays.len());
        for k in 0..backends.len() {
            let b = if s % 2 == 0 { k } else { backends.len() - 1 - k };
            let f = backends[b];
            let out = &mut outs[b][start..end];
            let cpu_ns = std::sync::atomic::AtomicU64::new(0);
            let t = Instant::now();
            pool.install(|| {
                out.par_chunks_mut(CHUNK).zip(rays[start..end].par_chunks(CHUNK)).enumerate().for_each(|(c, (o, r))| {
                    let c0 = thread_cpu_seconds();
                    for (i, (o, r)) in o.iter_mut().zip(r).enumerate() {
                        *o = f(start + c * CHUNK + i, r);
                    }
                    let ns = ((thread_cpu_seconds() - c0) * 1e9) as u64;
                    cpu_ns.fetch_add(ns, std::sync::atomic::Ordering::Relaxed);
                })
            });
            secs[b].wall += t.elapsed().as_secs_f64();
            secs[b].cpu += cpu_ns.into_inner() as f64 * 1e-9;
        }
    }
    secs
}

/// Medians over runs of wall-clock and CPU-time throughput, in Mrays/s.
struct Rates {
    wall: f64,
    cpu: f64,
}

fn rates(n: f64, runs: &[Secs]) -> Rates {
    let mut w: Vec<f64> = runs.iter().map(|s| s.wall).collect();
    let mut c: Vec<f64> = runs.iter().map(|s| s.cpu).collect();
    Rates { wall: n / median(&mut w) / 1e6, cpu: n / median(&mut c) / 1e6 }
}

/// Median wall and CPU seconds (each taken separately).
fn median_secs(v: &[Secs]) -> Secs {
    let mut w: Vec<f64> = v.iter().map(|s| s.wall).collect();
    let mut c: Vec<f64> = v.iter().map(|s| s.cpu).collect();
    Secs { wall: median(&mut w), cpu: median(&mut c) }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Closest-hit result as (t, prim); a miss is (∞, u32::MAX).
type Closest = (f32, u32);
const MISS: Closest = (f32::INFINITY, u32::MAX);

fn bench_scene(spec: &str, scene: &radiosity::scene::Scene, a: &RaysArgs, pool: &rayon::ThreadPool) -> Result<()> {
    let (tris, tri_poly) = triangles(scene);
    let (lo, hi) = scene.bounds();
    let diag = (hi - lo).length();
    println!("\nscene {spec}: {} polygons, {} triangles", scene.polygons.len(), tris.len());
    if tris.is_empty() {
        println!("  no triangles, skipped");
        return Ok(());
    }
    let set = make_rays(&tris, &tri_poly, a.rays, a.seed, diag);
    let n = a.rays as f64;
    let runs = a.runs;

    // Build: wall clock and process CPU time (all threads), medians over the runs.
    let mut ours_build = Vec::new();
    let mut bvh = Bvh::default();
    for _ in 0..runs {
        let (c, t) = (process_cpu_seconds(), Instant::now());
        bvh = pool.install(|| Bvh::build(&tris));
        ours_build.push(Secs { wall: t.elapsed().as_secs_f64(), cpu: process_cpu_seconds() - c });
    }
    let ours_build = median_secs(&ours_build);
    let scene_rays = SceneRays::new(&scene.polygons);

    #[cfg(feature = "embree")]
    let (emb, emb_build, emb_mem) = {
        let mut times = Vec::new();
        let mut emb = None;
        let mut mem = 0;
        let mut config = format!("threads={}", a.threads);
        if !a.embree_config.is_empty() {
            config = format!("{config},{}", a.embree_config);
        }
        for run in 0..runs {
            drop(emb.take());
            let rss0 = rss_bytes();
            let (c, t) = (process_cpu_seconds(), Instant::now());
            let e = radiosity_embree::EmbreeScene::build(&tris, &config, radiosity_embree::Quality::Medium)?;
            times.push(Secs { wall: t.elapsed().as_secs_f64(), cpu: process_cpu_seconds() - c });
            if run == 0 {
                // Later builds reuse freed pages; only the first growth means something.
                mem = rss_bytes().saturating_sub(rss0);
            }
            emb = Some(e);
        }
        let emb = emb.expect("runs > 0");
        println!("  embree {}", emb.describe());
        (emb, median_secs(&times), mem)
    };

    let st = bvh.stats();
    println!(
        "  tree       ours: {} nodes ({:.2} children), {} leaves ({:.2} triangles, {} packets), depth {}, SAH {:.2} = nodes {:.2} + leaves {:.2}",
        st.nodes,
        st.children_per_node,
        st.leaves,
        st.triangles_per_leaf,
        st.packets,
        st.depth,
        st.sah_nodes + st.sah_leaves,
        st.sah_nodes,
        st.sah_leaves
    );
    print!(
        "  build      ours {:>8.2} ms, CPU {:>8.2} ms ({:.1} MiB)",
        ours_build.wall * 1e3,
        ours_build.cpu * 1e3,
        bvh.memory_bytes() as f64 / (1 << 20) as f64
    );
    #[cfg(feature = "embree")]
    print!(
        " | embree {:>8.2} ms, CPU {:>8.2} ms (≈{:.1} MiB RSS) | ours/embree time {:.2} (CPU {:.2})",
        emb_build.wall * 1e3,
        emb_build.cpu * 1e3,
        emb_mem as f64 / (1 << 20) as f64,
        ours_build.wall / emb_build.wall,
        ours_build.cpu / emb_build.cpu
    );
    println!();

    // Closest hit.
    let ours_q = |_: usize, r: &Ray| bvh.intersect(r).map_or(MISS, |h| (h.t, h.prim));
    #[allow(unused_mut)]
    let mut backends: Vec<Query<Closest>> = vec![&ours_q];
    #[cfg(feature = "embree")]
    let emb_q = |_: usize, r: &Ray| emb.intersect(&to_embree(r)).map_or(MISS, |h| (h.t, h.prim));
    #[cfg(feature = "embree")]
    backends.push(&emb_q);
    // Embree's 8-ray packets: the ray at each multiple of 8 traces itself and the next 7.
    #[cfg(feature = "embree")]
    let emb8_q = |i: usize, _: &Ray| {
        if i % 8 != 0 {
            return MISS;
        }
        let m = 8.min(set.closest.len() - i);
        let rays: [_; 8] = std::array::from_fn(|k| to_embree(&set.closest[i + k.min(m - 1)]));
        let mut out = [None; 8];
        emb.intersect8(&rays[..m], &mut out);
        out[0].map_or(MISS, |h| (h.t, h.prim))
    };
    #[cfg(feature = "embree")]
    if a.packets {
        backends.push(&emb8_q);
    }
    let mut outs = vec![vec![MISS; a.rays]; backends.len()];
    let mut secs = vec![Vec::new(); backends.len()];
    for _ in 0..runs {
        for (b, t) in race(pool, &set.closest, &mut outs, &backends).into_iter().enumerate() {
            secs[b].push(t);
        }
    }
    let hits = outs[0].iter().filter(|h| h.1 != u32::MAX).count() as f64 / n;
    let ours = rates(n, &secs[0]);
    #[cfg(feature = "embree")]
    let agree = outs[0].iter().zip(&outs[1]).filter(|(x, y)| same_hit(**x, **y)).count() as f64 / n;
    #[cfg(feature = "embree")]
    let emb_r = Some((rates(n, &secs[1]), agree));
    #[cfg(not(feature = "embree"))]
    let emb_r = None;
    report("closest", &ours, emb_r, &format!("hits {:.1} %", hits * 100.0));
    #[cfg(feature = "embree")]
    if a.packets {
        packet_line("rtcIntersect8", &rates(n, &secs[1]), &rates(n, &secs[2]));
    }

    // Any hit on segments; the solver's filtered visibility query races along.
    let ours_q = |_: usize, r: &Ray| bvh.occluded(r);
    let vis_q = |i: usize, r: &Ray| {
        let (pa, pb) = set.segment_polys[i];
        let b = r.origin + r.dir;
        !scene_rays.visible(r.origin.as_dvec3(), pa, b.as_dvec3(), pb)
    };
    #[allow(unused_mut)]
    let mut backends: Vec<Query<bool>> = vec![&ours_q, &vis_q];
    #[cfg(feature = "embree")]
    let emb_q = |_: usize, r: &Ray| emb.occluded(&to_embree(r));
    #[cfg(feature = "embree")]
    backends.push(&emb_q);
    #[cfg(feature = "embree")]
    let emb8_q = |i: usize, _: &Ray| {
        if i % 8 != 0 {
            return false;
        }
        let m = 8.min(set.segments.len() - i);
        let rays: [_; 8] = std::array::from_fn(|k| to_embree(&set.segments[i + k.min(m - 1)]));
        let mut out = [false; 8];
        emb.occluded8(&rays[..m], &mut out);
        out[0]
    };
    #[cfg(feature = "embree")]
    if a.packets {
        backends.push(&emb8_q);
    }
    let mut outs = vec![vec![false; a.rays]; backends.len()];
    let mut secs = vec![Vec::new(); backends.len()];
    for _ in 0..runs {
        for (b, t) in race(pool, &set.segments, &mut outs, &backends).into_iter().enumerate() {
            secs[b].push(t);
        }
    }
    let blocked = |o: &[bool]| o.iter().filter(|&&b| b).count() as f64 / n;
    let ours = rates(n, &secs[0]);
    #[cfg(feature = "embree")]
    let agree = outs[0].iter().zip(&outs[2]).filter(|(x, y)| x == y).count() as f64 / n;
    #[cfg(feature = "embree")]
    let emb_r = Some((rates(n, &secs[2]), agree));
    #[cfg(not(feature = "embree"))]
    let emb_r = None;
    report("any-hit", &ours, emb_r, &format!("occluded {:.1} %", blocked(&outs[0]) * 100.0));
    #[cfg(feature = "embree")]
    {
        // Where the two disagree, is the segment in an axis-aligned plane (a zero direction
        // component)? Embree clamps such components away from zero and so skips boxes the
        // segment lies exactly on the face of; we count those as entered.
        let differ: Vec<usize> = (0..a.rays).filter(|&i| outs[0][i] != outs[2][i]).collect();
        let planar = differ.iter().filter(|&&i| set.segments[i].dir.to_array().contains(&0.0)).count();
        let ours_only = differ.iter().filter(|&&i| outs[0][i]).count();
        if !differ.is_empty() {
            println!(
                "  any-hit    {} segments differ: {} blocked for us only; {} lie in an axis-aligned plane",
                differ.len(),
                ours_only,
                planar
            );
        }
    }
    #[cfg(feature = "embree")]
    if a.packets {
        packet_line("rtcOccluded8", &rates(n, &secs[2]), &rates(n, &secs[3]));
    }
    let vis = rates(n, &secs[1]);
    println!(
        "  visible    ours {:>6.2} Mrays/s, {:>6.2} per CPU-s  (SceneRays::visible: end polygons filtered; occluded {:.1} %)",
        vis.wall,
        vis.cpu,
        blocked(&outs[1]) * 100.0
    );

    #[cfg(not(feature = "embree"))]
    if a.packets {
        println!("  packets    (need --features embree)");
    }
    Ok(())
}

/// One line of results: ours, and Embree's with the ratios when present.
fn report(what: &str, ours: &Rates, emb: Option<(Rates, f64)>, extra: &str) {
    print!("  {what:<10} ours {:>6.2} Mrays/s, {:>6.2} per CPU-s", ours.wall, ours.cpu);
    if let Some((e, agree)) = emb {
        print!(
            " | embree {:>6.2}, {:>6.2} per CPU-s | ratio {:.2} (CPU {:.2}) | agree {:.3} %",
            e.wall,
            e.cpu,
            ours.wall / e.wall,
            ours.cpu / e.cpu,
            agree * 100.0
        );
    }
    println!(" | {extra}");
}

/// Embree's 8-ray packets against its single rays, raced in the same slices.
#[cfg(feature = "embree")]
fn packet_line(what: &str, single: &Rates, packet: &Rates) {
    println!(
        "  packets    embree {what} {:>6.2} Mrays/s, {:>6.2} per CPU-s | {:.2}× its single rays (CPU {:.2}×) (incoherent 8-ray packets)",
        packet.wall,
        packet.cpu,
        packet.wall / single.wall,
        packet.cpu / single.cpu
    );
}

#[cfg(feature = "embree")]
fn to_embree(r: &Ray) -> radiosity_embree::EmbreeRay {
    radiosity_embree::EmbreeRay { origin: r.origin, dir: r.dir, tmin: r.tmin, tmax: r.tmax }
}

/// Both miss, or both hit at the same distance (coincident triangles — two-sided
/// surfaces — may tie with different ids).
#[cfg(feature = "embree")]
fn same_hit(a: Closest, b: Closest) -> bool {
    a.1 == b.1 || (a.1 != u32::MAX && b.1 != u32::MAX && (a.0 - b.0).abs() <= 1e-4 * a.0.max(1e-3))
}

/// Resident set size of this process (Linux; 0 elsewhere).
#[cfg(feature = "embree")]
fn rss_bytes() -> usize {
    std::fs::read_to_string("/proc/self/statm")
        .ok()
        .and_then(|s| s.split_whitespace().nth(1).and_then(|p| p.parse::<usize>().ok()))
        .map_or(0, |pages| pages * 4096)
}

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("model name")).map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string()))
        .unwrap_or_else(|| "unknown CPU".into())
}
