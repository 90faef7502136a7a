//! `radiosity compare`: relative RMSE of an image against a reference (both EXR).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Args;
use radiosity::output::{self, metrics};

use crate::common::write_atomic;

/// Flags of `radiosity compare`.
#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The image to check (linear EXR).
    pub image: PathBuf,
    /// The reference (linear EXR, same size).
    pub reference: PathBuf,
    /// Mask threshold: reference pixels with a channel above this (and their 1-pixel ring)
    /// are excluded from the masked metric.
    #[arg(long, default_value_t = 1.0)]
    pub light_threshold: f64,
    /// Write a per-pixel relative-error heat map (PNG).
    #[arg(long, value_name = "FILE")]
    pub heatmap: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

pub fn run(a: CompareArgs) -> Result<ExitCode> {
    if a.light_threshold.is_nan() || a.light_threshold <= 0.0 {
        anyhow::bail!("--light-threshold must be a positive number (inf masks nothing), not {}", a.light_threshold);
    }
    if let Some(p) = &a.heatmap {
        let mut o = crate::common::Outputs::default();
        o.add_format("--heatmap", p, "png", "PNG");
        o.check()?;
    }
    let img = output::exr::read(&a.image)?;
    let reference = output::exr::read(&a.reference)?;
    let all = metrics::relative_rmse(&img, &reference, None)?;
    let mask = metrics::light_mask(&reference, a.light_threshold);
    let masked = metrics::relative_rmse(&img, &reference, Some(&mask)).map_err(|_| {
        anyhow::anyhow!(
            "every reference pixel is above --light-threshold {} (or next to one); raise the threshold for this scene's units",
            a.light_threshold
        )
    })?;
    if a.json {
        println!(
            "{}",
            serde_json::json!({
                "width": img.width, "height": img.height,
                "relative_rmse": all, "relative_rmse_light_masked": masked,
            })
        );
    } else {
        println!("image {}x{}", img.width, img.height);
        println!("relative RMSE (all pixels):    {:.4} ({:.2} %)", all, all * 100.0);
        println!("relative RMSE (light masked):  {:.4} ({:.2} %)", masked, masked * 100.0);
    }
    if let Some(p) = &a.heatmap {
        let png = metrics::heatmap_png(&img, &reference)?;
        write_atomic(p, &png)?;
    }
    Ok(ExitCode::SUCCESS)
}
