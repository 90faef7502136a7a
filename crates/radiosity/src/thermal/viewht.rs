//! ViewHT's inputs and its heat-flux table (Walton, NIST View3D suite): a View3D
//! view-factor text file (format 0) and a temperature file give each surface's net
//! radiative flux `qᵢ = σ Σⱼ ℱᵢⱼ (Tᵢ⁴ − Tⱼ⁴)` (positive when the surface loses heat; ViewHT
//! itself prints the opposite sign).
//!
//! - **View-factor file** (what `View3D` and `radiosity viewfactors -o F.txt` write): a
//!   header `program version format encl didemit n`, then `n` areas, `n × n` factors row by
//!   row, `n` emissivities (numbers may wrap over lines). With `didemit = 1` the factors
//!   are already View3D's emittance-weighted ones, `ℱ = εB`; with `didemit = 0` they are
//!   geometric `F` and the grey exchange is formed here from the file's emissivities
//!   ([`super::total_exchange_factors`]; ViewHT would treat such surfaces as black).
//! - **Temperature file**: lines `n1 n2 T` set surfaces `n1..=n2` (1-based, either order; a
//!   range past the last surface stops there, as in ViewHT) to `T` kelvin; a line whose
//!   first number is 0 ends the data; `!` starts a comment. Later lines win.
//!
//! What leaves the surfaces and is not absorbed by another surface (an open geometry,
//! rows of `ℱ` summing to less than `εᵢ`) goes to an environment at `T_env`.

use std::path::Path;

use super::{total_exchange_factors, STEFAN_BOLTZMANN};
use crate::{Error, Location, Result};

/// A View3D view-factor text file.
#[derive(Clone, Debug, PartialEq)]
pub struct ViewFactorFile {
    /// Program and version of the header.
    pub program: String,
    /// Header `encl`: the enclosure correction was applied.
    pub enclosure: bool,
    /// Header `didemit`: the factors are emittance-weighted (`ℱ = εB`).
    pub emittances: bool,
    /// Areas.
    pub areas: Vec<f64>,
    /// Factors, row-major `n × n`.
    pub factors: Vec<f64>,
    /// Emissivities.
    pub emissivity: Vec<f64>,
}

impl ViewFactorFile {
    /// Number of surfaces.
    pub fn len(&self) -> usize {
        self.areas.len()
    }
    /// True without surfaces.
    pub fn is_empty(&self) -> bool {
        self.areas.is_empty()
    }
}

/// Reads a View3D view-factor text file (format 0) from disk.
pub fn load_view_factor_file(path: &Path) -> Result<ViewFactorFile> {
    parse_view_factor_file(&crate::scene::obj::read_text(path)?, path)
}

/// Reads a ViewHT temperature file for `n` surfaces from disk.
pub fn load_temperatures(path: &Path, n: usize) -> Result<Vec<Option<f64>>> {
    parse_temperatures(&crate::scene::obj::read_text(path)?, path, n)
}

/// Words of `text` with their 1-based line numbers (`!` comments dropped).
fn words(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines().enumerate().flat_map(|(k, line)| {
        let line = line.split('!').next().unwrap_or("");
        line.split([' ', '\t', ',']).filter(|w| !w.is_empty()).map(move |w| (k + 1, w))
    })
}

/// Reads a View3D view-factor text file (format 0).
pub fn parse_view_factor_file(text: &str, path: &Path) -> Result<ViewFactorFile> {
    let loc = |line: usize| Location::line(path, line);
    let mut w = words(text).peekable();
    let header: Vec<(usize, &str)> = w.by_ref().take(6).collect();
    if header.len() < 6 || header.iter().any(|(l, _)| *l != 1) {
        return Err(Error::input(
            loc(1),
            "not a View3D view-factor file: the first line must be 'program version format encl didemit n'",
        ));
    }
    let int = |k: usize, what: &str| -> Result<i64> {
        header[k].1.parse().map_err(|_| Error::input(loc(1), format!("{what} '{}' is not an integer", header[k].1)))
    };
    let format = int(2, "format")?;
    if format != 0 {
        return Err(Error::input(loc(1), format!("format {format}: only View3D's text format 0 is read")));
    }
    let enclosure = int(3, "encl")? != 0;
    let emittances = int(4, "didemit")? != 0;
    let n = int(5, "surface count")?;
    if !(1..=100_000).contains(&n) {
        return Err(Error::input(loc(1), format!("surface count {n} must be 1 to 100000")));
    }
    let n = n as usize;
    let mut last = 1;
    let mut take = |count: usize, what: &str| -> Result<Vec<f64>> {
        let mut v = Vec::with_capacity(count);
        for k in 0..count {
            let Some((line, word)) = w.next() else {
                return Err(Error::input(
                    loc(last),
                    format!("the file ends after {k} of {count} {what} (header says {n} surfaces)"),
                ));
            };
            last = line;
            let x: f64 = word
                .parse()
                .ok()
                .filter(|x: &f64| x.is_finite())
                .ok_or_else(|| Error::input(loc(line), format!("{what}: '{word}' is not a finite number")))?;
            v.push(x);
        }
        Ok(v)
    };
    let areas = take(n, "areas")?;
    let factors = take(n * n, "view factors")?;
    let emissivity = take(n, "emissivities")?;
    if let Some(i) = areas.iter().position(|a| !(*a > 0.0)) {
        return Err(Error::input(loc(2), format!("area {} of surface {} must be positive", areas[i], i + 1)));
    }
    if let Some(k) = factors.iter().position(|f| *f < 0.0) {
        return Err(Error::input(
            loc(1),
            format!("view factor [{}][{}] = {} is negative", k / n + 1, k % n + 1, factors[k]),
        ));
    }
    if let Some(i) = emissivity.iter().position(|e| !(*e > 0.0 && *e <= 1.0)) {
        return Err(Error::input(
            loc(last),
            format!("emissivity {} of surface {} is not in (0, 1]", emissivity[i], i + 1),
        ));
    }
    Ok(ViewFactorFile {
        program: format!("{} {}", header[0].1, header[1].1),
        enclosure,
        emittances,
        areas,
        factors,
        emissivity,
    })
}

/// Reads a ViewHT temperature file for `n` surfaces: each surface's temperature, `None`
/// where the file gives none.
pub fn parse_temperatures(text: &str, path: &Path, n: usize) -> Result<Vec<Option<f64>>> {
    let mut t = vec![None; n];
    for (k, line) in text.lines().enumerate() {
        let loc = Location::line(path, k + 1);
        let w: Vec<&str> =
            line.split('!').next().unwrap_or("").split([' ', '\t', ',']).filter(|w| !w.is_empty()).collect();
        if w.is_empty() {
            continue;
        }
        let index = |s: &str| -> Result<i64> {
            s.parse().map_err(|_| Error::input(loc.clone(), format!("surface number '{s}' is not an integer")))
        };
        let n1 = index(w[0])?;
        if n1 == 0 {
            break;
        }
        if w.len() < 3 {
            return Err(Error::input(loc, "expected 'first last T' (surfaces first..=last at T kelvin)"));
        }
        let n2 = index(w[1])?;
        // As ViewHT: the order of the two is free and a range past the last surface ends there.
        let (a, b) = (n1.min(n2), n1.max(n2).min(n as i64));
        if a < 1 || a as usize > n {
            return Err(Error::input(loc, format!("surfaces {n1}..{n2}: the surfaces are numbered 1 to {n}")));
        }
        let temp: f64 = w[2].parse().map_err(|_| Error::input(loc.clone(), format!("'{}' is not a number", w[2])))?;
        if !(temp.is_finite() && temp >= 0.0) {
            return Err(Error::input(loc, format!("temperature {temp} K must be finite and ≥ 0")));
        }
        for s in &mut t[a as usize - 1..b as usize] {
            *s = Some(temp);
        }
    }
    Ok(t)
}

/// One row of the heat table.
#[derive(Clone, Debug, serde::Serialize)]
pub struct HeatRow {
    /// Area.
    pub area: f64,
    /// Emissivity.
    pub emissivity: f64,
    /// Temperature, K.
    pub temperature: f64,
    /// Net flux leaving, W per unit area.
    pub heat_flux: f64,
    /// Net heat leaving, W.
    pub heat: f64,
}

/// ViewHT's table.
#[derive(Clone, Debug, serde::Serialize)]
pub struct HeatTable {
    /// Per surface.
    pub rows: Vec<HeatRow>,
    /// Net heat the environment receives, W.
    pub environment_heat: f64,
    /// ΣQ − Q_env, W.
    pub balance: f64,
    /// Σ|Q| + |Q_env|, W.
    pub total: f64,
    /// Largest relative reciprocity error of `Aᵢℱᵢⱼ` (pairs above 1e-12 of the largest).
    pub reciprocity: f64,
    /// Whether the grey exchange was formed from geometric factors (`didemit = 0`).
    pub formed_exchange: bool,
}

/// Heat fluxes of the surfaces of `vf` at temperatures `t` (kelvin), the rest of each row
/// going to an environment at `environment` K.
pub fn heat_table(vf: &ViewFactorFile, t: &[f64], environment: f64) -> Result<HeatTable> {
    let n = vf.len();
    if t.len() != n {
        return Err(Error::Invalid(format!("{} temperatures for {n} surfaces", t.len())));
    }
    let sf = if vf.emittances { vf.factors.clone() } else { total_exchange_factors(&vf.factors, &vf.emissivity)? };
    let s = STEFAN_BOLTZMANN;
    let t4 = |x: f64| x * x * x * x;
    let mut rows = Vec::with_capacity(n);
    let mut environment_heat = 0.0;
    for i in 0..n {
        let row = &sf[i * n..(i + 1) * n];
        // What leaves i and is absorbed nowhere in the geometry reaches the environment.
        let lost = (vf.emissivity[i] - row.iter().sum::<f64>()).max(0.0);
        let to_environment = s * lost * (t4(t[i]) - t4(environment));
        let q = s * row.iter().zip(t).map(|(f, tj)| f * (t4(t[i]) - t4(*tj))).sum::<f64>() + to_environment;
        environment_heat += to_environment * vf.areas[i];
        rows.push(HeatRow {
            area: vf.areas[i],
            emissivity: vf.emissivity[i],
            temperature: t[i],
            heat_flux: q,
            heat: q * vf.areas[i],
        });
    }
    let sum: f64 = rows.iter().map(|r| r.heat).sum();
    let total = rows.iter().map(|r| r.heat.abs()).sum::<f64>() + environment_heat.abs();
    let reciprocity = super::reciprocity_error(n, |i, j| vf.areas[i] * sf[i * n + j]);
    Ok(HeatTable {
        rows,
        environment_heat,
        balance: sum - environment_heat,
        total,
        reciprocity,
        formed_exchange: !vf.emittances,
    })
}
