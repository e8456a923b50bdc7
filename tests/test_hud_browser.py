"""The `<pedas-hud>` web component in Debian's headless Chromium: every Fig. 7 situation drawn as its frame says,
the arrow's length follows arrow_len, the warning tone sounds once per warning, and `hud fig7` writes the PNGs."""
from __future__ import annotations

import shutil

import pytest

from pedas.hud_frame import FIG7, fig7_frames
from tests.conftest import OUTPUT as OUTPUT_ROOT
from tests.conftest import needs_chromium

OUTPUT = OUTPUT_ROOT / "hud"

pytestmark = [
    pytest.mark.browser,
    needs_chromium,
]


@pytest.fixture(scope="module")
def page():
    from playwright.sync_api import sync_playwright

    from pedas.hud_png import hud_script, launch

    with sync_playwright() as p:
        b = launch(p)
        pg = b.new_page()
        pg.set_content(f"<!doctype html><script>{hud_script()}</script><pedas-hud id='hud' sound "
                       f"style='width:480px'></pedas-hud>")
        yield pg
        b.close()


SHOWN = """el => {
  const r = el.shadowRoot, vis = id => r.getElementById(id).style.display !== 'none';
  return {speed: r.getElementById('speed').textContent, fill: r.getElementById('speed').getAttribute('fill'),
          arrow: vis('arrow') ? r.getElementById('arrow').getAttribute('stroke') : null,
          arrow_len: vis('arrow') ? Number(r.getElementById('arrow').dataset.length) : 0,
          tip_up: vis('arrow') ? /M350 (\\d+\\.?\\d*) L350 (\\d+\\.?\\d*)/.exec(r.getElementById('arrow').getAttribute('d'))
                                   .slice(1).map(Number).reduce((a, b) => a > b) : null,
          limit: vis('limit') ? r.getElementById('limit-text').textContent : null,
          countdown: vis('countdown') ? r.getElementById('countdown-text').textContent : null,
          icons: ['green_wave', 'stop_sign', 'curve'].filter(i => vis('icon-' + i)),
          warning: vis('warning'), tones: Number(el.dataset.tones)};
}"""
COLOURS = {"black": "#111", "green": "#0a9d3c", "red": "#d2161e"}


def draw(page, frame: dict) -> dict:
    hud = page.locator("#hud")
    hud.evaluate("(el, f) => { el.frame = f; }", frame)
    return hud.evaluate(SHOWN)


@pytest.mark.parametrize("sit", FIG7, ids=[s.key for s in FIG7])
def test_each_fig7_situation_is_drawn_as_its_frame_says(page, sit):
    f = sit.frame()
    draw(page, {**f.as_dict(), "warning": False})     # start from no warning so a warning frame sounds
    shown = draw(page, f.as_dict())
    assert shown["speed"] == str(f.speed) and shown["fill"] == COLOURS[f.color]
    assert shown["limit"] == (None if f.limit is None else str(f.limit))
    if f.arrow == 0:
        assert shown["arrow"] is None
    else:
        assert shown["arrow"] == COLOURS[f.color]
        assert shown["tip_up"] == (f.arrow > 0)      # tail below the tip (SVG y grows downwards) for "up"
    assert shown["countdown"] == (None if f.countdown is None else str(f.countdown))
    assert shown["icons"] == ([f.icon] if f.icon else [])
    assert shown["warning"] == f.warning


def test_arrow_length_and_tone(page):
    base = fig7_frames()["a"].as_dict()
    short = draw(page, {**base, "arrow_len": 0.1})["arrow_len"]
    long = draw(page, {**base, "arrow_len": 0.9})["arrow_len"]
    assert short == pytest.approx(28 + 92 * 0.1, abs=0.06) and long == pytest.approx(28 + 92 * 0.9, abs=0.06)
    tones = draw(page, base)["tones"]
    assert draw(page, {**base, "warning": True})["tones"] == tones + 1      # switched on: one tone
    assert draw(page, {**base, "warning": True})["tones"] == tones + 1      # still on: no new tone
    draw(page, base)
    assert draw(page, {**base, "warning": True})["tones"] == tones + 2      # on again: a second tone


def test_cli_writes_the_nine_pngs(cli_proc, tmp_path):
    """Through the CLI in its own process (one Playwright per thread: the page fixture holds this one's)."""
    import numpy as np
    from PIL import Image

    out = tmp_path / "fig7"
    r = cli_proc("hud", "fig7", "--out", out, db=None, timeout=300)
    assert r.code == 0, r.err
    assert r.out.count(".png") == 9 and "fig7.html" in r.out
    images = {k: Image.open(out / f"fig7_{k}.png").convert("RGB") for k in "abcdefghi"}
    assert {im.size for im in images.values()} == {images["a"].size} and images["a"].size[0] == 480
    assert len({im.tobytes() for im in images.values()}) == 9          # nine different pictures
    # green digits in (a), red in (b), black in (c): count pixels of each colour
    def count(im, rgb):
        return int((np.abs(np.asarray(im, int) - rgb) < 12).all(axis=2).sum())
    assert count(images["a"], (10, 157, 60)) > 2000 and count(images["a"], (210, 22, 30)) < count(images["b"], (210, 22, 30))
    assert count(images["c"], (10, 157, 60)) == 0
    OUTPUT.mkdir(parents=True, exist_ok=True)
    for k in "abcdefghi":
        shutil.copy(out / f"fig7_{k}.png", OUTPUT / f"fig7_{k}.png")
