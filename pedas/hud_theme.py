"""HUD themes: the colours of ``<pedas-hud>`` (pedas/web/hud.js) and their WCAG 2.x contrast ratios.

- ``light``: the opaque light panel of a dashboard screen (the paper's Fig. 7: black digits inside the band).
- ``dark``: for a projected or combiner HUD, where black emits no light and so is see-through: a black panel,
  bright glyphs. The paper's "black digits" inside the band would vanish on it, so the in-band digits are white
  (docs/hud.md).

Every glyph is listed with the background it is drawn on (:func:`glyph_pairs`); each pair must reach a contrast
ratio of at least :data:`MIN_CONTRAST` (WCAG 2.x, success criterion 1.4.3, normal text), checked by the tests.
"""
from __future__ import annotations

MIN_CONTRAST = 4.5   # WCAG 2.x SC 1.4.3 (AA) for text

THEMES: dict[str, dict[str, str]] = {
    "light": {
        "panel": "#eef1f4", "border": "#c9ced4", "divider": "#b9c0c8", "label": "#555555",
        "black": "#111111", "green": "#087a2e", "red": "#c8141c",
        "disc": "#ffffff", "ring": "#d2161e", "limit_text": "#111111",
        "tile": "#087a2e", "tile_text": "#ffffff", "stop": "#c8141c", "stop_text": "#ffffff",
        "sign": "#ffffff", "curve_arrow": "#111111", "warn": "#f2c200", "warn_text": "#111111",
        "housing": "#222222", "lamp_off": "#4a4a4a", "timer": "#222222",
        "lamp_red": "#ff4b4b", "lamp_yellow": "#ffd21f", "lamp_green": "#2fd46a", "alarm": "#d2161e",
        "alarm_blink": "#f3a5a8", "page": "#ffffff",
    },
    "dark": {
        "panel": "#000000", "border": "#3a3f45", "divider": "#3a3f45", "label": "#b8b8b8",
        "black": "#ffffff", "green": "#3ee07a", "red": "#ff5c5c",
        "disc": "#ffffff", "ring": "#e0191f", "limit_text": "#111111",
        "tile": "#087a2e", "tile_text": "#ffffff", "stop": "#c8141c", "stop_text": "#ffffff",
        "sign": "#ffffff", "curve_arrow": "#111111", "warn": "#f2c200", "warn_text": "#111111",
        "housing": "#1c1c1c", "lamp_off": "#3a3a3a", "timer": "#000000",
        "lamp_red": "#ff4b4b", "lamp_yellow": "#ffd21f", "lamp_green": "#2fd46a", "alarm": "#ff3b3b",
        "alarm_blink": "#5a1010", "page": "#000000",
    },
}

#: glyph -> (its colour's key, its background's key) in a theme
GLYPHS: dict[str, tuple[str, str]] = {
    "speed digits, coast (in band)": ("black", "panel"),
    "speed digits and arrow, speed up": ("green", "panel"),
    "speed digits and arrow, slow down": ("red", "panel"),
    "km/h label": ("label", "panel"),
    "speed limit digits": ("limit_text", "disc"),
    "G of the green-wave icon": ("tile_text", "tile"),
    "STOP of the stop sign": ("stop_text", "stop"),
    "arrow of the curve sign": ("curve_arrow", "sign"),
    "! of the warning triangle": ("warn_text", "warn"),
    "countdown digits, red phase": ("lamp_red", "timer"),
    "countdown digits, yellow phase": ("lamp_yellow", "timer"),
    "countdown digits, green phase": ("lamp_green", "timer"),
}


def check_theme(name: str) -> str:
    """The theme name, or ValueError (one line) naming the themes there are."""
    if name not in THEMES:
        raise ValueError(f"unknown HUD theme {name!r}: choose one of {', '.join(THEMES)}")
    return name


def relative_luminance(hex_colour: str) -> float:
    """WCAG 2.x relative luminance of an sRGB colour '#rrggbb' (0 black .. 1 white)."""
    h = hex_colour.lstrip("#")
    out = []
    for i in (0, 2, 4):
        c = int(h[i:i + 2], 16) / 255.0
        out.append(c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4)
    return 0.2126 * out[0] + 0.7152 * out[1] + 0.0722 * out[2]


def contrast_ratio(a: str, b: str) -> float:
    """WCAG 2.x contrast ratio (L1 + 0.05) / (L2 + 0.05) of two colours, 1..21."""
    la, lb = sorted((relative_luminance(a), relative_luminance(b)), reverse=True)
    return (la + 0.05) / (lb + 0.05)


def glyph_pairs(theme: str) -> list[tuple[str, str, str, float]]:
    """Per glyph of a theme: (glyph, colour, background, contrast ratio)."""
    t = THEMES[check_theme(theme)]
    return [(g, t[fg], t[bg], contrast_ratio(t[fg], t[bg])) for g, (fg, bg) in GLYPHS.items()]
