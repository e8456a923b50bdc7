"""HUD themes: WCAG 2.x contrast of every glyph against its background, in both themes."""
from __future__ import annotations

import pytest

from pedas.hud_theme import GLYPHS, MIN_CONTRAST, THEMES, check_theme, contrast_ratio, glyph_pairs, relative_luminance


def test_contrast_formula_against_hand_worked_values():
    # WCAG: black on white 21:1, white on white 1:1; #777777 on white 4.48:1 (the classic "just fails AA" grey)
    assert contrast_ratio("#000000", "#ffffff") == pytest.approx(21.0)
    assert contrast_ratio("#ffffff", "#ffffff") == pytest.approx(1.0)
    assert contrast_ratio("#777777", "#ffffff") == pytest.approx(4.48, abs=0.005)
    assert relative_luminance("#ff0000") == pytest.approx(0.2126)
    assert contrast_ratio("#0a9d3c", "#eef1f4") < MIN_CONTRAST     # the old green digits on the light panel


@pytest.mark.parametrize("theme", sorted(THEMES))
def test_every_glyph_reaches_4_5_to_1(theme):
    pairs = glyph_pairs(theme)
    assert len(pairs) == len(GLYPHS)
    low = [(g, round(r, 2)) for g, _, _, r in pairs if r < MIN_CONTRAST]
    assert not low, low


def test_dark_theme_has_no_black_digits_and_unknown_theme_is_refused():
    assert THEMES["dark"]["black"] != "#111111" and THEMES["dark"]["panel"] == "#000000"
    with pytest.raises(ValueError, match="unknown HUD theme 'blue'"):
        check_theme("blue")
