//! What every plot of the lab shares: one palette, one font and one legend box. plotters draws text only with a
//! font registered at run time: [`fonts_available`] loads DejaVu Sans from [`FONT_PATH`] once (Debian's
//! `fonts-dejavu-core`). Without it the plots are drawn without any text (no caption, tick
//! labels or legend) instead of failing, and the reports say so.

use plotters::chart::{ChartContext, SeriesLabelPosition};
use plotters::coord::CoordTranslate;
use plotters::drawing::DrawingAreaErrorKind;
use plotters::prelude::DrawingBackend;
use plotters::style::{BLACK, Color, FontStyle, RGBColor, WHITE};
use std::sync::OnceLock;

/// Line colours: strong and distinct on white (plotters' Palette99 starts with pale yellows),
/// black first for the baseline of a chart.
pub const PALETTE: [RGBColor; 10] = [
    RGBColor(0, 0, 0),
    RGBColor(214, 39, 40),
    RGBColor(31, 119, 180),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

/// Where the plots' font is looked for.
pub const FONT_PATH: &str = "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf";

/// Registers DejaVu Sans as plotters' `sans-serif` once; whether text can be drawn.
pub fn fonts_available() -> bool {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    *REGISTERED.get_or_init(|| {
        let Ok(bytes) = std::fs::read(FONT_PATH) else {
            tracing::warn!("{FONT_PATH} not found: plots are drawn without text");
            return false;
        };
        let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
        plotters::style::register_font("sans-serif", FontStyle::Normal, bytes).is_ok()
    })
}

/// Draws the legend of the series labelled so far at `position`: a white box with a black
/// border and 14 px text (needs [`fonts_available`]).
///
/// # Errors
/// What the drawing backend reports.
pub fn legend<'a, DB, CT>(
    chart: &mut ChartContext<'a, DB, CT>,
    position: SeriesLabelPosition,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: DrawingBackend + 'a,
    CT: CoordTranslate,
{
    chart
        .configure_series_labels()
        .position(position)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", 14))
        .draw()
}
