//! View-factor matrices as files, written row by row so that a large matrix is streamed to
//! its destination rather than assembled in memory a second time.
//!
//! - **CSV**: a header `surface,area,<names…>`, then one line per row `name,area,F…`
//!   (shortest round-trip decimal, so no precision is lost).
//! - **NumPy `.npy`** (format 1.0): the `n × n` matrix as little-endian f64, C order.
//! - **JSON**: `names`, `areas`, `emissivity`, `method`, `per`, `convention`, `matrix`
//!   (array of rows), then whatever the caller adds at the end (diagnostics …).
//! - **View3D text** (View3D's output format 0): a header line
//!   `program version format encl didemit n`, the areas, one row of `F` per line with six
//!   decimals (View3D's own precision, so lossy), then the emissivities.
//!
//! The encoders write to any [`std::io::Write`]; creating (atomically) the file is the
//! program's business.

use std::io::{self, Write};
use std::path::Path;
use std::str::FromStr;

use crate::{Error, Result};

/// A matrix file format.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MatrixFormat {
    /// Comma-separated values with names.
    Csv,
    /// NumPy `.npy`.
    Npy,
    /// JSON with names, areas and diagnostics.
    Json,
    /// View3D's text output (format 0).
    View3d,
}

impl MatrixFormat {
    /// Every format.
    pub const ALL: [MatrixFormat; 4] = [MatrixFormat::Csv, MatrixFormat::Npy, MatrixFormat::Json, MatrixFormat::View3d];

    /// The name used by `--format`.
    pub fn name(self) -> &'static str {
        match self {
            MatrixFormat::Csv => "csv",
            MatrixFormat::Npy => "npy",
            MatrixFormat::Json => "json",
            MatrixFormat::View3d => "view3d",
        }
    }

    /// The format of a file name's extension (`.csv`, `.npy`, `.json`, `.txt`/`.vf`).
    pub fn from_path(path: &Path) -> Option<MatrixFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "csv" => Some(MatrixFormat::Csv),
            "npy" => Some(MatrixFormat::Npy),
            "json" => Some(MatrixFormat::Json),
            "txt" | "vf" => Some(MatrixFormat::View3d),
            _ => None,
        }
    }
}

impl FromStr for MatrixFormat {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        MatrixFormat::ALL.iter().copied().find(|f| f.name() == s).ok_or_else(|| {
            Error::Invalid(format!("unknown matrix format '{s}' (known: csv, npy, json, view3d)"))
        })
    }
}

/// What is written around the numbers.
#[derive(Clone, Debug)]
pub struct MatrixMeta<'a> {
    /// Scene name or title.
    pub title: &'a str,
    /// Row/column names.
    pub names: &'a [String],
    /// Areas.
    pub areas: &'a [f64],
    /// Emissivities (View3D output, JSON).
    pub emissivity: &'a [f64],
    /// Method name.
    pub method: &'a str,
    /// "object" or "element".
    pub per: &'a str,
    /// Whether the enclosure correction was applied (View3D header).
    pub enclosure: bool,
    /// Whether the values are View3D's emittance-weighted factors `ℱᵢⱼ = εᵢBᵢⱼ` rather than
    /// `F` (View3D header `didemit`, JSON `convention`).
    pub emittances: bool,
}

/// Writes one matrix, a row at a time.
pub struct MatrixWriter<W: Write> {
    format: MatrixFormat,
    w: W,
    n: usize,
    rows: usize,
    names: Vec<String>,
    areas: Vec<f64>,
    emissivity: Vec<f64>,
}

impl<W: Write> MatrixWriter<W> {
    /// Writes the header.
    pub fn begin(format: MatrixFormat, mut w: W, meta: &MatrixMeta) -> io::Result<Self> {
        let n = meta.names.len();
        match format {
            MatrixFormat::Csv => {
                write!(w, "surface,area")?;
                for name in meta.names {
                    write!(w, ",{}", csv_field(name))?;
                }
                writeln!(w)?;
            }
            MatrixFormat::Npy => {
                let mut header = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': ({n}, {n}), }}");
                // Magic (6) + version (2) + length (2) + header + '\n' ≡ 0 (mod 64).
                while (10 + header.len() + 1) % 64 != 0 {
                    header.push(' ');
                }
                header.push('\n');
                w.write_all(b"\x93NUMPY\x01\x00")?;
                w.write_all(&(header.len() as u16).to_le_bytes())?;
                w.write_all(header.as_bytes())?;
            }
            MatrixFormat::Json => {
                let s = |v: &dyn erased::Ser| v.json();
                write!(w, "{{\n \"scene\": {},\n \"method\": {},\n \"per\": {},\n", s(&meta.title), s(&meta.method), s(&meta.per))?;
                let convention = if meta.emittances {
                    "F[i][j] = emissivity[i] * B[i][j], B[i][j] = fraction of the emission of surface i absorbed by surface j after any diffuse reflections (View3D's emittance-weighted factors, Hottel's script-F)"
                } else {
                    "F[i][j] = fraction of the energy leaving surface i (diffusely, from its front side) that arrives at surface j"
                };
                writeln!(w, " \"convention\": {},", s(&convention))?;
                write!(w, " \"names\": {},\n \"areas\": {},\n", s(&meta.names), s(&meta.areas))?;
                write!(w, " \"emissivity\": {},\n \"matrix\": [", s(&meta.emissivity))?;
            }
            MatrixFormat::View3d => {
                let mut header =
                    format!(
                    "radiosity {} 0 {} {} {n}",
                    env!("CARGO_PKG_VERSION"),
                    u8::from(meta.enclosure),
                    u8::from(meta.emittances)
                );
                while header.len() < 30 {
                    header.push(' ');
                }
                writeln!(w, "{header}")?;
                let areas: Vec<String> = meta.areas.iter().map(|a| format!("{a}")).collect();
                writeln!(w, "{}", areas.join(" "))?;
            }
        }
        Ok(MatrixWriter {
            format,
            w,
            n,
            rows: 0,
            names: meta.names.to_vec(),
            areas: meta.areas.to_vec(),
            emissivity: meta.emissivity.to_vec(),
        })
    }

    /// Writes the next row (`n` values).
    pub fn row(&mut self, row: &[f64]) -> io::Result<()> {
        assert_eq!(row.len(), self.n, "row length");
        let i = self.rows;
        assert!(i < self.n, "more rows than columns");
        let w = &mut self.w;
        match self.format {
            MatrixFormat::Csv => {
                write!(w, "{},{}", csv_field(&self.names[i]), self.areas[i])?;
                for v in row {
                    write!(w, ",{v}")?;
                }
                writeln!(w)?;
            }
            MatrixFormat::Npy => {
                let mut buf = Vec::with_capacity(row.len() * 8);
                for v in row {
                    buf.extend_from_slice(&v.to_le_bytes());
                }
                w.write_all(&buf)?;
            }
            MatrixFormat::Json => {
                write!(w, "{}\n  [", if i == 0 { "" } else { "," })?;
                for (k, v) in row.iter().enumerate() {
                    let s = if v.is_finite() { format!("{v:?}") } else { "null".into() };
                    write!(w, "{}{}", if k == 0 { "" } else { ", " }, s)?;
                }
                write!(w, "]")?;
            }
            MatrixFormat::View3d => {
                let cells: Vec<String> = row.iter().map(|v| format!("{v:.6}")).collect();
                writeln!(w, "{}", cells.join(" "))?;
            }
        }
        self.rows += 1;
        Ok(())
    }

    /// Ends the file; for JSON, `extra` (an object's fields) is written after the matrix.
    pub fn finish(mut self, extra: &serde_json::Map<String, serde_json::Value>) -> io::Result<W> {
        if self.rows != self.n {
            return Err(io::Error::other(format!("{} rows written of {}", self.rows, self.n)));
        }
        let w = &mut self.w;
        match self.format {
            MatrixFormat::Csv | MatrixFormat::Npy => {}
            MatrixFormat::Json => {
                write!(w, "\n ]")?;
                for (k, v) in extra {
                    let text = serde_json::to_string_pretty(v).map_err(io::Error::other)?;
                    write!(w, ",\n {}: {}", serde_json::Value::String(k.clone()), text.replace('\n', "\n "))?;
                }
                writeln!(w, "\n}}")?;
            }
            MatrixFormat::View3d => {
                let e: Vec<String> = self.emissivity.iter().map(|v| format!("{v:.3}")).collect();
                writeln!(w, "{}", e.join(" "))?;
            }
        }
        w.flush()?;
        Ok(self.w)
    }
}

/// Formats of a truncated (sparse) matrix.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SparseFormat {
    /// Matrix Market coordinate format (`.mtx`; `scipy.io.mmread`), 1-based, with the
    /// names and areas as comments.
    MatrixMarket,
    /// CSV triplets `row,column,row_name,column_name,value` (0-based indices).
    Csv,
    /// JSON: names, areas, CSR arrays `row_ptr`, `cols`, `vals`, then the extras.
    Json,
}

impl SparseFormat {
    /// The format of a file name's extension (`.mtx`, `.csv`, `.json`).
    pub fn from_path(path: &Path) -> Option<SparseFormat> {
        match path.extension()?.to_str()?.to_ascii_lowercase().as_str() {
            "mtx" => Some(SparseFormat::MatrixMarket),
            "csv" => Some(SparseFormat::Csv),
            "json" => Some(SparseFormat::Json),
            _ => None,
        }
    }
}

/// Writes a truncated matrix.
pub fn write_sparse<W: Write>(
    format: SparseFormat,
    mut w: W,
    meta: &MatrixMeta,
    m: &crate::form_factor::sparse::SparseMatrix,
    extra: &serde_json::Map<String, serde_json::Value>,
) -> io::Result<W> {
    let n = m.n;
    let what = if meta.emittances { "emittance-weighted factors eps_i B_ij" } else { "view factors F_ij" };
    match format {
        SparseFormat::MatrixMarket => {
            writeln!(w, "%%MatrixMarket matrix coordinate real general")?;
            writeln!(w, "% {}: {what}, truncated and rebalanced (radiosity {})", meta.title, env!("CARGO_PKG_VERSION"))?;
            for (k, (name, a)) in meta.names.iter().zip(meta.areas).enumerate() {
                writeln!(w, "% {} area {a} name {}", k + 1, name.replace('\n', " "))?;
            }
            writeln!(w, "{n} {n} {}", m.nnz())?;
            for i in 0..n {
                let (c, v) = m.row(i);
                for (j, f) in c.iter().zip(v) {
                    writeln!(w, "{} {} {f:e}", i + 1, j + 1)?;
                }
            }
        }
        SparseFormat::Csv => {
            writeln!(w, "row,column,row_name,column_name,value")?;
            for i in 0..n {
                let (c, v) = m.row(i);
                for (&j, f) in c.iter().zip(v) {
                    writeln!(w, "{i},{j},{},{},{f}", csv_field(&meta.names[i]), csv_field(&meta.names[j as usize]))?;
                }
            }
        }
        SparseFormat::Json => {
            let s = |v: &dyn erased::Ser| v.json();
            write!(w, "{{\n \"scene\": {},\n \"method\": {},\n \"per\": {},\n", s(&meta.title), s(&meta.method), s(&meta.per))?;
            writeln!(w, " \"values\": {},", s(&what))?;
            write!(w, " \"names\": {},\n \"areas\": {},\n", s(&meta.names), s(&meta.areas))?;
            write!(w, " \"row_ptr\": {},\n \"cols\": {},\n \"vals\": {}", s(&m.row_ptr), s(&m.cols), s(&m.vals))?;
            for (k, v) in extra {
                let text = serde_json::to_string_pretty(v).map_err(io::Error::other)?;
                write!(w, ",\n {}: {}", serde_json::Value::String(k.clone()), text.replace('\n', "\n "))?;
            }
            writeln!(w, "\n}}")?;
        }
    }
    w.flush()?;
    Ok(w)
}

/// A CSV field, quoted when it holds a comma, quote or line break.
fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n', '\r']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

mod erased {
    /// JSON text of a value (infallible for the plain types used here).
    pub trait Ser {
        fn json(&self) -> String;
    }
    impl<T: serde::Serialize + ?Sized> Ser for T {
        fn json(&self) -> String {
            serde_json::to_string(self).unwrap_or_else(|_| "null".into())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(format: MatrixFormat) -> Vec<u8> {
        let names = vec!["a,1".to_string(), "b".to_string()];
        let meta = MatrixMeta {
            title: "t",
            names: &names,
            areas: &[1.0, 2.0],
            emissivity: &[0.9, 0.5],
            method: "analytic",
            per: "object",
            enclosure: false,
            emittances: false,
        };
        let mut w = MatrixWriter::begin(format, Vec::new(), &meta).unwrap();
        w.row(&[0.0, 0.25]).unwrap();
        w.row(&[0.125, 0.1]).unwrap();
        let mut extra = serde_json::Map::new();
        extra.insert("diagnostics".into(), serde_json::json!({"x": 1}));
        w.finish(&extra).unwrap()
    }

    #[test]
    fn csv_and_json_round_trip_the_values() {
        let csv = String::from_utf8(write(MatrixFormat::Csv)).unwrap();
        assert_eq!(csv, "surface,area,\"a,1\",b\n\"a,1\",1,0,0.25\nb,2,0.125,0.1\n");
        let json: serde_json::Value = serde_json::from_slice(&write(MatrixFormat::Json)).unwrap();
        assert_eq!(json["matrix"][1][0], 0.125);
        assert_eq!(json["names"][0], "a,1");
        assert_eq!(json["diagnostics"]["x"], 1);
    }

    #[test]
    fn npy_header_is_aligned_and_data_little_endian() {
        let b = write(MatrixFormat::Npy);
        assert_eq!(&b[..8], b"\x93NUMPY\x01\x00");
        let hl = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + hl) % 64, 0);
        assert!(std::str::from_utf8(&b[10..10 + hl]).unwrap().contains("'shape': (2, 2)"));
        let data = &b[10 + hl..];
        assert_eq!(data.len(), 32);
        assert_eq!(f64::from_le_bytes(data[8..16].try_into().unwrap()), 0.25);
    }

    #[test]
    fn view3d_text_has_header_areas_rows_emissivities() {
        let t = String::from_utf8(write(MatrixFormat::View3d)).unwrap();
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines.len(), 5);
        assert!(lines[0].starts_with("radiosity ") && lines[0].ends_with("0 0 0 2") || lines[0].contains(" 0 0 0 2"));
        assert_eq!(lines[2], "0.000000 0.250000");
        assert_eq!(lines[4], "0.900 0.500");
    }
}
