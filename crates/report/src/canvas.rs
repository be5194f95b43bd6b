//! The machinery every picture shares: choosing PNG or SVG from the file name, registering the
//! embedded font, and small drawing helpers in pixel coordinates.

use std::path::Path;
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::*;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use plotters::style::{FontDesc, FontFamily, FontStyle, RGBAColor};

use crate::color::Rgb;
use crate::error::{ReportError, Result};
use crate::glyphs::CrispText;

/// The font family name every picture uses; the embedded DejaVu Sans is registered under it. It is
/// also the family name written into SVG files, where the viewer's own sans-serif font is used.
pub(crate) const FAMILY: &str = "sans-serif";

/// Picture file formats, chosen by the output file's extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// A PNG bitmap (`.png`).
    Png,
    /// An SVG vector picture (`.svg`); text stays text.
    Svg,
}

impl Format {
    /// The format for an output path: `.png` or `.svg`, case-insensitive.
    pub fn of(path: &Path) -> Result<Format> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("png") => Ok(Format::Png),
            Some("svg") => Ok(Format::Svg),
            _ => Err(ReportError::UnsupportedFormat {
                path: path.to_path_buf(),
            }),
        }
    }
}

/// Registers DejaVu Sans (regular, bold, oblique) with plotters once per process. plotters is
/// built with `ab_glyph` and without `font-kit`, so no system font library is ever consulted.
pub(crate) fn ensure_fonts() -> Result<()> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        let styles = [
            (FontStyle::Normal, dejavu::sans::regular()),
            (FontStyle::Bold, dejavu::sans::bold()),
            (FontStyle::Oblique, dejavu::sans::oblique()),
            (FontStyle::Italic, dejavu::sans::oblique()),
        ];
        styles
            .into_iter()
            .all(|(style, bytes)| plotters::style::register_font(FAMILY, style, bytes).is_ok())
    });
    if ok { Ok(()) } else { Err(ReportError::Font) }
}

/// A drawing failure inside a picture, before the output path is attached.
#[derive(Debug)]
pub(crate) struct Fail(pub String);

impl<E: std::error::Error + Send + Sync> From<DrawingAreaErrorKind<E>> for Fail {
    fn from(e: DrawingAreaErrorKind<E>) -> Self {
        Fail(e.to_string())
    }
}

/// Result of drawing code.
pub(crate) type Drawn<T = ()> = std::result::Result<T, Fail>;

/// A picture that can draw itself on any plotters backend.
pub(crate) trait Picture {
    /// Width and height in pixels.
    fn size(&self) -> (u32, u32);
    /// Draws the whole picture on `root`, whose coordinates are pixels from the top left;
    /// `format` lets it pick a coarser sampling for vector output.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, format: Format) -> Drawn;
}

/// Draws `picture` into `out`, as PNG or SVG by the file's extension.
pub(crate) fn render(picture: &impl Picture, out: &Path) -> Result<()> {
    let format = Format::of(out)?;
    ensure_fonts()?;
    let size = picture.size();
    let fail = |message: String| ReportError::Draw {
        path: out.to_path_buf(),
        message,
    };
    match format {
        Format::Png => {
            let root = CrispText::new(BitMapBackend::new(out, size)).into_drawing_area();
            root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
            picture.draw(&root, format).map_err(|f| fail(f.0))?;
            root.present().map_err(|e| fail(e.to_string()))?;
        }
        Format::Svg => {
            let root = SVGBackend::new(out, size).into_drawing_area();
            root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
            picture.draw(&root, format).map_err(|f| fail(f.0))?;
            root.present().map_err(|e| fail(e.to_string()))?;
        }
    }
    tracing::debug!(path = %out.display(), width = size.0, height = size.1, "picture written");
    Ok(())
}

/// A font of the embedded family.
pub(crate) fn font(size: f64, style: FontStyle) -> FontDesc<'static> {
    FontDesc::new(FontFamily::Name(FAMILY), size, style)
}

/// Pixel size of `text` in `font`. Falls back to a rough estimate if the font cannot measure,
/// which only happens when registration failed (and then drawing fails anyway).
pub(crate) fn text_size(font: &FontDesc<'_>, text: &str) -> (f64, f64) {
    match font.box_size(text) {
        Ok((w, h)) => (f64::from(w), f64::from(h)),
        Err(_) => (
            text.chars().count() as f64 * font.get_size() * 0.6,
            font.get_size(),
        ),
    }
}

/// A colour with opacity.
pub(crate) fn rgba(c: Rgb, alpha: f64) -> RGBAColor {
    c.rgb().mix(alpha)
}

/// Draws `text` with its anchor at `pos` (pixels).
pub(crate) fn text<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    text: &str,
    pos: (f64, f64),
    font: &FontDesc<'_>,
    color: Rgb,
    anchor: (HPos, VPos),
) -> Drawn {
    let rgb = color.rgb();
    let style = TextStyle::from(font.clone())
        .color(&rgb)
        .pos(Pos::new(anchor.0, anchor.1));
    root.draw_text(text, &style, px(pos))?;
    Ok(())
}

/// A pixel coordinate from a fractional one.
pub(crate) fn px(p: (f64, f64)) -> (i32, i32) {
    (p.0.round() as i32, p.1.round() as i32)
}

/// A thick segment as a filled quadrilateral, extended by `extend` pixels at both ends. Drawing
/// thick lines as polygons gives clean wall joins in both backends.
pub(crate) fn thick_segment<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    a: (f64, f64),
    b: (f64, f64),
    width: f64,
    extend: f64,
    color: RGBAColor,
) -> Drawn {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len = dx.hypot(dy);
    if len < 1e-9 {
        return Ok(());
    }
    let (ux, uy) = (dx / len, dy / len);
    let (nx, ny) = (-uy * width / 2.0, ux * width / 2.0);
    let a = (a.0 - ux * extend, a.1 - uy * extend);
    let b = (b.0 + ux * extend, b.1 + uy * extend);
    let quad = vec![
        px((a.0 + nx, a.1 + ny)),
        px((b.0 + nx, b.1 + ny)),
        px((b.0 - nx, b.1 - ny)),
        px((a.0 - nx, a.1 - ny)),
    ];
    root.draw(&Polygon::new(quad, color.filled()))?;
    Ok(())
}

/// A polyline of the given width: filled quads per segment with round joins, so thick paths are
/// crisp (no anti-aliased stroke edges) and do not break at corners.
pub(crate) fn polyline<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    points: &[(f64, f64)],
    width: f64,
    color: RGBAColor,
) -> Drawn {
    for w in points.windows(2) {
        thick_segment(root, w[0], w[1], width, 0.0, color)?;
    }
    if width > 2.0 && points.len() > 2 {
        let r = (width / 2.0).round().max(1.0) as u32;
        for p in &points[1..points.len() - 1] {
            root.draw(&Circle::new(px(*p), r, color.filled()))?;
        }
    }
    Ok(())
}

/// A filled triangular arrow head at `tip`, pointing along `dir` (pixels), `len` long.
pub(crate) fn arrow_head<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    tip: (f64, f64),
    dir: (f64, f64),
    len: f64,
    color: RGBAColor,
) -> Drawn {
    let n = dir.0.hypot(dir.1);
    if n < 1e-9 {
        return Ok(());
    }
    let (ux, uy) = (dir.0 / n, dir.1 / n);
    let base = (tip.0 - ux * len, tip.1 - uy * len);
    let half = len * 0.5;
    let tri = vec![
        px(tip),
        px((base.0 - uy * half, base.1 + ux * half)),
        px((base.0 + uy * half, base.1 - ux * half)),
    ];
    root.draw(&Polygon::new(tri, color.filled()))?;
    Ok(())
}

/// Splits `name` into lines no wider than `max_width` pixels, breaking after `/`, `+` or spaces
/// (strategy names like `llm+model/p-context-a/gpt-5-mini`). A single piece wider than
/// `max_width` stays on its own line.
pub(crate) fn wrap(name: &str, font: &FontDesc<'_>, max_width: f64) -> Vec<String> {
    let mut pieces: Vec<String> = Vec::new();
    let mut cur = String::new();
    for ch in name.chars() {
        if ch == ' ' {
            if !cur.is_empty() {
                pieces.push(std::mem::take(&mut cur));
            }
            continue;
        }
        cur.push(ch);
        if ch == '/' || ch == '+' {
            pieces.push(std::mem::take(&mut cur));
        }
    }
    if !cur.is_empty() {
        pieces.push(cur);
    }
    let mut lines: Vec<String> = Vec::new();
    let mut line = String::new();
    for piece in pieces {
        let joiner = if line.is_empty() || line.ends_with('/') || line.ends_with('+') {
            ""
        } else {
            " "
        };
        let candidate = format!("{line}{joiner}{piece}");
        if line.is_empty() || text_size(font, &candidate).0 <= max_width {
            line = candidate;
        } else {
            lines.push(std::mem::replace(&mut line, piece));
        }
    }
    if !line.is_empty() {
        lines.push(line);
    }
    lines
}

/// A "nice" tick step (1, 2 or 5 × 10^k) giving at most about `max_ticks` ticks over `span`.
pub(crate) fn nice_step(span: f64, max_ticks: f64) -> f64 {
    if !(span.is_finite() && span > 0.0) {
        return 1.0;
    }
    let raw = span / max_ticks.max(1.0);
    let mag = 10f64.powf(raw.log10().floor());
    for m in [1.0, 2.0, 5.0, 10.0] {
        if m * mag >= raw {
            return m * mag;
        }
    }
    10.0 * mag
}

/// Formats an axis number for plotters' label formatters: at most six significant digits, no
/// trailing zeros (`10`, `2.5`, `0.05`).
pub(crate) fn axis_number(v: &f64) -> String {
    if *v == 0.0 || !v.is_finite() {
        return "0".into();
    }
    let digits = (5 - v.abs().log10().floor() as i32).clamp(0, 12) as usize;
    let s = format!("{v:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" { "0".into() } else { s }
}

/// Formats a tick value without trailing zeros.
pub(crate) fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10()).ceil() as usize
    };
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_follows_extension() {
        assert_eq!(Format::of(Path::new("a/b.PNG")).ok(), Some(Format::Png));
        assert_eq!(Format::of(Path::new("plan.svg")).ok(), Some(Format::Svg));
        assert!(Format::of(Path::new("plan.jpg")).is_err());
        assert!(Format::of(Path::new("plan")).is_err());
    }

    #[test]
    fn nice_steps() {
        assert_eq!(nice_step(10.0, 10.0), 1.0);
        assert_eq!(nice_step(17.0, 10.0), 2.0);
        assert_eq!(nice_step(40.0, 10.0), 5.0);
        assert_eq!(nice_step(0.7, 7.0), 0.1);
        assert_eq!(tick_label(2.0, 1.0), "2");
        assert_eq!(tick_label(0.30000000000000004, 0.1), "0.3");
        assert_eq!(axis_number(&10.0), "10");
        assert_eq!(axis_number(&140.0), "140");
        assert_eq!(axis_number(&0.30000000000000004), "0.3");
        assert_eq!(axis_number(&2.5), "2.5");
        assert_eq!(axis_number(&-0.0), "0");
    }

    #[test]
    fn wrapping_breaks_after_slashes() {
        ensure_fonts().unwrap();
        let f = font(12.0, FontStyle::Normal);
        let lines = wrap("llm+model/p-context-a/gpt-5-mini", &f, 80.0);
        assert!(lines.len() >= 2, "{lines:?}");
        assert_eq!(lines.concat(), "llm+model/p-context-a/gpt-5-mini");
        assert_eq!(wrap("oracle", &f, 200.0), vec!["oracle".to_string()]);
    }
}
