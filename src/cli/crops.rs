//! Folders of ball crops as `topspin logo` reads them: `frames.csv`
//! (`file,t,u,v,radius`) beside 8-bit RGB(A) PNGs, placed on the sensor by
//! `crop_origin`. Shared by `topspin logo` and its CNN paths.

use std::path::Path;

use super::BadInput;
use topspin_core::logo::Circle;
use topspin_core::wire::crop_origin;

/// One decoded crop of a folder.
#[derive(Debug)]
pub struct FolderFrame {
    pub t: f64,
    pub circle: Circle,
    pub x0: i64,
    pub y0: i64,
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<u8>,
}

pub fn read_folder(folder: &Path) -> Result<Vec<FolderFrame>, BadInput> {
    let csv_path = folder.join("frames.csv");
    let name = csv_path.display();
    if !folder.is_dir() {
        return Err(BadInput(format!("{}: not a folder", folder.display())));
    }
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(&csv_path)
        .map_err(|e| BadInput(format!("{name}: {e}")))?;
    let headers = reader.headers().map_err(|e| BadInput(format!("{name}: {e}")))?.clone();
    let column = |key: &str| {
        headers
            .iter()
            .position(|h| h == key)
            .ok_or_else(|| BadInput(format!("{name}: header has no column `{key}` (expected file,t,u,v,radius)")))
    };
    let cols = [column("file")?, column("t")?, column("u")?, column("v")?, column("radius")?];
    let mut out = Vec::new();
    for (row, record) in reader.records().enumerate() {
        let record = record.map_err(|e| BadInput(format!("{name}: data row {row}: {e}")))?;
        let mut v = [0.0; 4];
        for (k, &c) in cols[1..].iter().enumerate() {
            let text = record.get(c).unwrap_or("");
            v[k] = text
                .parse::<f64>()
                .ok()
                .filter(|x| x.is_finite())
                .ok_or_else(|| BadInput(format!("{name}: data row {row}: `{text}` is not a finite number")))?;
        }
        if v[3] <= 0.0 {
            return Err(BadInput(format!("{name}: data row {row}: radius {} must be positive", v[3])));
        }
        let file = record.get(cols[0]).unwrap_or("");
        let (width, height, rgb) =
            read_png(&folder.join(file)).map_err(|e| BadInput(format!("{name}: data row {row}: {file}: {e}")))?;
        let (x0, y0) = crop_origin(v[1], v[2], width as u32, height as u32);
        out.push(FolderFrame {
            t: v[0],
            circle: Circle { u: v[1], v: v[2], radius: v[3] },
            x0,
            y0,
            width,
            height,
            rgb,
        });
    }
    if out.windows(2).any(|w| w[1].t <= w[0].t) {
        return Err(BadInput(format!("{name}: times must increase")));
    }
    Ok(out)
}

/// Decodes an 8-bit RGB or RGBA PNG into RGB8.
pub fn read_png(path: &Path) -> Result<(usize, usize, Vec<u8>), String> {
    let file = std::fs::File::open(path).map_err(|e| e.to_string())?;
    let decoder = png::Decoder::new(std::io::BufReader::new(file));
    let mut reader = decoder.read_info().map_err(|e| e.to_string())?;
    let size = reader.output_buffer_size().ok_or("PNG too large")?;
    let mut buf = vec![0u8; size];
    let info = reader.next_frame(&mut buf).map_err(|e| e.to_string())?;
    if info.bit_depth != png::BitDepth::Eight {
        return Err(format!("{:?}-bit PNG (need 8-bit RGB)", info.bit_depth));
    }
    let (w, h) = (info.width as usize, info.height as usize);
    if w == 0 || h == 0 || w > 96 || h > 96 {
        return Err(format!("crop of {w} × {h} px (each side 1..=96)"));
    }
    let px = w * h;
    let rgb = match info.color_type {
        png::ColorType::Rgb => buf[..3 * px].to_vec(),
        png::ColorType::Rgba => buf[..4 * px].chunks_exact(4).flat_map(|c| [c[0], c[1], c[2]]).collect(),
        other => return Err(format!("{other:?} PNG (need RGB or RGBA)")),
    };
    Ok((w, h, rgb))
}
