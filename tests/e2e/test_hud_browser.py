"""The `<pedas-hud>` web component in Debian's headless Chromium: every Fig. 7 situation drawn as its frame says,
the arrow's length follows arrow_len, the warning tone sounds once per warning, and `hud fig7` writes the PNGs."""
from __future__ import annotations

import shutil

import pytest

from pedas.hud_frame import FIG7, fig7_frames
from pedas.hud_theme import THEMES
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
          tip_up: vis('arrow') ? /M258 (\\d+\\.?\\d*) L258 (\\d+\\.?\\d*)/.exec(r.getElementById('arrow').getAttribute('d'))
                                   .slice(1).map(Number).reduce((a, b) => a > b) : null,
          limit: vis('limit') ? r.getElementById('limit-text').textContent : null,
          countdown: vis('countdown') ? r.getElementById('countdown-text').textContent : null,
          icons: ['green_wave', 'stop_sign', 'yield_sign', 'curve'].filter(i => vis('icon-' + i)),
          lamps: ['red', 'yellow', 'green'].filter(l => r.getElementById('lamp-' + l).getAttribute('fill') !== 'LAMP_OFF'),
          warning: vis('warning'), tones: Number(el.dataset.tones)};
}""".replace("LAMP_OFF", THEMES["light"]["lamp_off"])
COLOURS = {k: THEMES["light"][k] for k in ("black", "green", "red")}


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
    assert shown["lamps"] == ([f.light] if f.countdown is not None else [])


def test_arrow_length_and_tone(page):
    base = fig7_frames()["a"].as_dict()
    short = draw(page, {**base, "arrow_len": 0.1})["arrow_len"]
    long = draw(page, {**base, "arrow_len": 0.9})["arrow_len"]
    assert short == pytest.approx(30 + 160 * 0.1, abs=0.06) and long == pytest.approx(30 + 160 * 0.9, abs=0.06)
    tones = draw(page, base)["tones"]
    assert draw(page, {**base, "warning": True})["tones"] == tones + 1      # switched on: one tone
    assert draw(page, {**base, "warning": True})["tones"] == tones + 1      # still on: no new tone
    draw(page, base)
    assert draw(page, {**base, "warning": True})["tones"] == tones + 2      # on again: a second tone


BOXES = """el => {
  // boxes in the 480 x 270 view's units, from the rendered boxes (groups are translated)
  const r = el.shadowRoot, s = r.querySelector('svg').getBoundingClientRect(), k = 480 / s.width,
        box = id => { const b = r.getElementById(id).getBoundingClientRect();
                      return [(b.left - s.left) * k, (b.top - s.top) * k, (b.right - s.left) * k, (b.bottom - s.top) * k]; };
  return {speed: box('speed'), arrow: box('arrow'), limit: box('limit'), countdown: box('countdown'),
          text: r.getElementById('speed').textContent};
}"""


@pytest.mark.parametrize("speed", [0, 99, 100, 188])
def test_speeds_up_to_three_digits_fit_left_of_the_arrow(page, speed):
    """Region 1 (speed, limit below it) ends at x = 208 of the 480-wide view, the arrow is at x = 258 +- 14:
    the digits of 0..188 km/h, the limit under them and the full-length arrow do not overlap (screenshots in
    tests/output/hud/speed_<n>.png)."""
    frame = {"speed": speed, "advice": speed + 20, "limit": 120, "arrow": 1, "arrow_len": 1.0, "color": "green",
             "in_band": False, "countdown": 9, "light": "green", "icon": "green_wave", "warning": False}
    hud = page.locator("#hud")
    hud.evaluate("(el, f) => { el.frame = f; }", frame)
    b = hud.evaluate(BOXES)
    assert b["text"] == str(speed)
    assert 4 <= b["speed"][0] and b["speed"][2] <= 208 < b["arrow"][0]            # digits left of the arrow
    assert b["speed"][3] <= b["limit"][1]                                          # the limit below the speed
    assert b["arrow"][2] < 308 <= b["countdown"][0]                                # arrow left of region 3
    OUTPUT.mkdir(parents=True, exist_ok=True)
    hud.screenshot(path=str(OUTPUT / f"speed_{speed}.png"), animations="disabled")


def test_green_and_red_countdowns_differ_and_icons(page):
    """The counted-down phase's lamp is lit (green bottom, red top) and the digits take its colour; the G and
    the yield icon are drawn."""
    base = {"speed": 40, "advice": 40, "limit": 50, "arrow": 0, "arrow_len": 0, "color": "black", "in_band": True,
            "countdown": 6, "icon": None, "warning": False}
    green, red = draw(page, {**base, "light": "green"}), draw(page, {**base, "light": "red"})
    assert (green["lamps"], red["lamps"]) == (["green"], ["red"])
    digit = "el => el.shadowRoot.getElementById('countdown-text').getAttribute('fill')"
    draw(page, {**base, "light": "green"})
    g = page.locator("#hud").evaluate(digit)
    draw(page, {**base, "light": "red"})
    assert g != page.locator("#hud").evaluate(digit)
    assert draw(page, {**base, "icon": "yield_sign", "countdown": None})["icons"] == ["yield_sign"]
    icon_text = "el => el.shadowRoot.querySelector('#icon-green_wave text').textContent"
    assert page.locator("#hud").evaluate(icon_text) == "G"
    hud = page.locator("#hud")
    hud.evaluate("(el, f) => { el.frame = f; }", {**base, "icon": "yield_sign", "countdown": None})
    OUTPUT.mkdir(parents=True, exist_ok=True)
    hud.screenshot(path=str(OUTPUT / "yield_sign.png"), animations="disabled")


def test_cli_writes_the_nine_pngs(cli_proc, tmp_path):
    """Through the CLI in its own process (one Playwright per thread: the page fixture holds this one's)."""
    import numpy as np
    from PIL import Image

    out = tmp_path / "fig7"
    r = cli_proc("hud", "fig7", "--out", out, db=None, timeout=300)
    assert r.code == 0, r.err
    assert r.out.count(".png") == 9 and "fig7.html" in r.out and r.out.count("the paper: ") == 9
    for k in "abcdefghi":   # the text beside each PNG: letter, caption, the paper's sentence, the state
        text = (out / f"fig7_{k}.txt").read_text(encoding="utf-8")
        assert text.startswith(f"Fig. 7({k}) ") and "The paper: " in text and "State: P" in text
    images = {k: Image.open(out / f"fig7_{k}.png").convert("RGB") for k in "abcdefghi"}
    assert {im.size for im in images.values()} == {images["a"].size} and images["a"].size[0] == 480
    assert len({im.tobytes() for im in images.values()}) == 9          # nine different pictures
    # green digits in (e), red in (f), black in (d): count pixels of each colour
    def count(im, rgb):
        return int((np.abs(np.asarray(im, int) - rgb) < 12).all(axis=2).sum())
    rgb = {k: tuple(int(v[i:i + 2], 16) for i in (1, 3, 5)) for k, v in THEMES["light"].items()}
    assert count(images["e"], rgb["green"]) > 2000 and count(images["e"], rgb["red"]) < count(images["f"], rgb["red"])
    assert count(images["d"], rgb["green"]) == 0
    # the lit lamp: green in (h), red in (i)
    assert count(images["h"], rgb["lamp_green"]) > 200 and count(images["i"], rgb["lamp_green"]) == 0
    assert count(images["i"], rgb["lamp_red"]) > 200 and count(images["h"], rgb["lamp_red"]) == 0
    OUTPUT.mkdir(parents=True, exist_ok=True)
    for k in "abcdefghi":
        shutil.copy(out / f"fig7_{k}.png", OUTPUT / f"fig7_{k}.png")


REGION3 = """el => {
  const r = el.shadowRoot, s = r.querySelector('svg').getBoundingClientRect(), k = 480 / s.width,
        box = e => { const b = e.getBoundingClientRect();
                     return [(b.left - s.left) * k, (b.top - s.top) * k, (b.right - s.left) * k, (b.bottom - s.top) * k]; };
  const shown = ['icon-green_wave', 'icon-stop_sign', 'icon-yield_sign', 'icon-curve']
                  .map(id => r.getElementById(id)).filter(e => e.style.display !== 'none');
  return {icon: box(shown[0]), warning: box(r.getElementById('warning')),
          limit: box(r.getElementById('limit-text')), disc: box(r.getElementById('limit-disc'))};
}"""


@pytest.mark.parametrize("theme", sorted(THEMES))
@pytest.mark.parametrize("icon", ["green_wave", "stop_sign", "yield_sign", "curve"])
def test_region_3_full_keeps_its_glyphs_apart(page, theme, icon):
    """Region 3 full (an icon, the warning, a countdown): the icon starts >= 6 px right of the divider (x = 308),
    the warning >= 6 px right of the icon and >= 6 px inside the panel's edge (x = 476, border 10 px while it
    blinks); screenshots tests/output/hud/region3_<theme>_<icon>.png."""
    hud = page.locator("#hud")
    hud.evaluate("(el, t) => el.setAttribute('theme', t)", theme)
    frame = {"speed": 82, "advice": 60, "limit": 100, "arrow": -1, "arrow_len": 1.0, "color": "red",
             "in_band": False, "countdown": 3, "light": "yellow", "icon": icon, "warning": True}
    hud.evaluate("(el, f) => { el.frame = f; }", frame)
    b = hud.evaluate(REGION3)
    assert b["icon"][0] >= 308 + 6 and b["warning"][0] >= b["icon"][2] + 6 and b["warning"][2] <= 476 - 10 - 6
    OUTPUT.mkdir(parents=True, exist_ok=True)
    hud.screenshot(path=str(OUTPUT / f"region3_{theme}_{icon}.png"), animations="disabled")
    hud.evaluate("el => el.removeAttribute('theme')")


@pytest.mark.parametrize("theme", sorted(THEMES))
@pytest.mark.parametrize("limit", [30, 50, 100, 120])
def test_limits_fit_inside_the_disc_with_a_margin(page, theme, limit):
    """The limit's digits stay >= 8 px inside the disc's 84 px outer box (the ring is 9 px wide, so >= 3.5 px
    from the ring's inner edge); screenshots tests/output/hud/limit_<theme>_<n>.png."""
    hud = page.locator("#hud")
    hud.evaluate("(el, t) => el.setAttribute('theme', t)", theme)
    hud.evaluate("(el, f) => { el.frame = f; }", {"speed": 9, "advice": 9, "limit": limit, "arrow": 0, "arrow_len": 0,
                                                  "color": "black", "in_band": True, "countdown": None,
                                                  "light": None, "icon": None, "warning": False})
    b = hud.evaluate(REGION3.replace("shown[0]", "r.getElementById('speed')"))
    assert b["limit"][0] >= b["disc"][0] + 8 + 4.5 and b["limit"][2] <= b["disc"][2] - 8 - 4.5
    OUTPUT.mkdir(parents=True, exist_ok=True)
    hud.screenshot(path=str(OUTPUT / f"limit_{theme}_{limit}.png"), animations="disabled")
    hud.evaluate("el => el.removeAttribute('theme')")


def test_dark_theme_paints_its_colours_and_the_visual_warning_switches_off(page):
    hud = page.locator("#hud")
    frame = {**fig7_frames()["f"].as_dict(), "warning": True}
    fills = "el => ({panel: el.shadowRoot.getElementById('panel').getAttribute('fill'), " \
            "speed: el.shadowRoot.getElementById('speed').getAttribute('fill'), " \
            "warning: el.shadowRoot.getElementById('warning').style.display !== 'none'})"
    hud.evaluate("(el, f) => { el.setAttribute('theme', 'dark'); el.frame = f; }", frame)
    dark = hud.evaluate(fills)
    hud.evaluate("(el, f) => { el.setAttribute('no-visual-warning', ''); el.frame = f; }", frame)
    off = hud.evaluate(fills)
    hud.evaluate("el => { el.removeAttribute('theme'); el.removeAttribute('no-visual-warning'); }")
    light = hud.evaluate(fills)
    assert dark == {"panel": THEMES["dark"]["panel"], "speed": THEMES["dark"]["red"], "warning": True}
    assert off["warning"] is False and light["panel"] == THEMES["light"]["panel"]


@pytest.mark.parametrize("theme", sorted(THEMES))
def test_brake_state_fits_region_2_above_the_arrow(page, theme):
    """The brake state: BRAKE inside region 2 (x 208..308) above the full red arrow, not touching it; screenshots
    tests/output/hud/brake_state_<theme>.png."""
    hud = page.locator("#hud")
    hud.evaluate("(el, t) => el.setAttribute('theme', t)", theme)
    frame = {"speed": 82, "advice": 0, "limit": 120, "arrow": -1, "arrow_len": 1.0, "color": "red", "in_band": False,
             "countdown": None, "light": None, "icon": None, "warning": True, "brake": True}
    hud.evaluate("(el, f) => { el.frame = f; }", frame)
    b = hud.evaluate(REGION3.replace("shown[0]", "r.getElementById('brake')")
                     .replace("r.getElementById('limit-text')", "r.getElementById('arrow')"))
    brake, arrow = b["icon"], b["limit"]
    assert hud.get_attribute("data-brake") == "true"
    assert 208 + 4 <= brake[0] and brake[2] <= 308 - 4 and brake[3] + 4 <= arrow[1]
    OUTPUT.mkdir(parents=True, exist_ok=True)
    hud.screenshot(path=str(OUTPUT / f"brake_state_{theme}.png"), animations="disabled")
    hud.evaluate("(el, f) => { el.removeAttribute('theme'); el.frame = {...f, brake: false, warning: false}; }", frame)
    assert hud.get_attribute("data-brake") == "false"
