"""Animations of a run: the GIF's frames, the stick figure against closed forms and the C's
poses, the HTML viewer's escaping, and the viewer playing in a real headless browser."""
from __future__ import annotations

import contextlib
import json
import os
import re
from dataclasses import replace
from html.parser import HTMLParser

import numpy as np
import pytest

from modelgen.errors import ModelError, ModelgenError
from modelgen.model.scene import load_scene
from modelgen.model.spec import ModelSpec
from modelgen.sim import animate as anim
from modelgen.sim.result import Result
from modelgen.sim.scene import Scene

from conftest import MODELS, SCENES

CHROMIUM = os.environ.get("MODELGEN_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking",
                 "--disable-component-update", "--disable-sync"]
HOSTILE = "</script><script>alert(1)</script>"


@pytest.fixture(scope="module")
def dp(build_root):
    """The double pendulum's free scene over 2 s, and its run."""
    spec = replace(load_scene(SCENES / "dp_free.yaml"), t_end=2.0)
    scene = Scene(spec, build_root / "dp_free")
    return scene, scene.run()


def _hostile_motion() -> anim.Motion:
    t = np.linspace(0.0, 1.0, 11)
    positions = np.zeros((11, 2, 3))
    positions[:, 1, 0] = np.cos(3 * t)
    positions[:, 1, 1] = np.sin(3 * t)
    poses = np.tile(np.eye(4), (11, 1, 1, 1))
    poses[:, 0, :3, 3] = positions[:, 1]
    return anim.Motion(HOSTILE, t, ("O", HOSTILE + "&<!--"), ((0, 1),), positions,
                       (HOSTILE,), poses, (1,), np.eye(3), True, 0.15, 0.1, 1.0)


def test_gif_has_the_chosen_frames_and_they_differ(dp, tmp_path):
    from PIL import Image
    scene, res = dp
    path = scene.animate(res, tmp_path / "dp.gif", max_frames=20)
    with Image.open(path) as im:
        assert im.n_frames == 20
        frames = []
        for k in (0, 10, 19):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB"), dtype=int))
    assert all(np.abs(frames[0] - f).sum() > 0 for f in frames[1:])
    assert frames[0].std() > 0                       # something is drawn


def test_frames_play_in_real_time_by_default(dp):
    scene, res = dp
    m = anim.motion(res, scene.spec.model)           # 2 s at 25 frames per second
    assert m.n_frames == 51
    assert m.interval * (m.n_frames - 1) == pytest.approx(res.t[-1] - res.t[0])
    fast = anim.motion(res, scene.spec.model, speed=2.0, max_frames=10)
    assert fast.n_frames == 10
    assert fast.interval * (fast.n_frames - 1) == pytest.approx((res.t[-1] - res.t[0]) / 2)


def test_stick_figure_is_the_closed_form_and_the_c_body_poses(dp):
    scene, res = dp
    m = anim.motion(res, scene.spec.model, compiled=scene.model, max_frames=30)
    k = 17
    q1, q2 = np.interp(m.t[k], res.t, res["q1"]), np.interp(m.t[k], res.t, res["q2"])
    l1 = l2 = 1.0
    elbow = l1 * np.array([np.cos(q1), np.sin(q1), 0.0])
    G2 = elbow + l2 / 2 * np.array([np.cos(q1 + q2), np.sin(q1 + q2), 0.0])
    assert np.allclose(m.positions[k, m.points.index("P1")], elbow, atol=1e-12)
    assert np.allclose(m.positions[k, m.points.index("G2")], G2, atol=1e-12)
    assert np.allclose(m.positions[k, m.points.index("A")], [0, -3, 0])
    # the C's poses put each body's frame at the symbolic G, and agree with the symbolic poses
    for b, body in enumerate(scene.spec.model.bodies):
        assert np.allclose(m.poses[:, b, :3, 3], m.positions[:, m.points.index(body.G)],
                           atol=1e-12)
    symbolic = anim.motion(res, scene.spec.model, max_frames=30)
    assert np.allclose(symbolic.poses, m.poses, atol=1e-12)
    # the stick figure: O-P1, O-G1, P1-G2; the absolute point A is a dot only
    assert {(m.points[i], m.points[j]) for i, j in m.segments} == \
        {("O", "P1"), ("O", "G1"), ("P1", "G2")}
    assert [m.points[i] for i in m.trace] == ["G2"]
    # planar motion seen face on, up against gravity (-y)
    assert m.planar and np.allclose(m.view[2], [0, 0, 1]) and np.allclose(m.view[1], [0, 1, 0])


def test_a_3d_motion_gets_an_isometric_view_and_parameters_count():
    from modelgen.model.api import load_model
    spec: ModelSpec = load_model(MODELS / "heavy_top.yaml")
    rng = np.random.default_rng(3)
    t = np.linspace(0, 1, 21)
    y = np.vstack([np.cumsum(rng.normal(0, 0.3, (spec.n, 21)), axis=1),
                   np.zeros((spec.n, 21))])
    res = Result(t=t, y=y)
    m = anim.motion(res, spec, p={"a": 2.0})
    g = m.positions[:, m.points.index("G")]
    assert np.allclose(np.linalg.norm(g, axis=1), 2.0)     # G at distance a from O
    assert not m.planar
    assert np.allclose(m.view[1] @ [0, 0, 1], np.sqrt(2 / 3))   # isometric, z up
    with pytest.raises(ModelgenError, match="unknown parameter 'zz'"):
        anim.motion(res, spec, p={"zz": 1.0})


def test_unknown_trace_point_and_missing_ffmpeg_are_clear_errors(dp, tmp_path, monkeypatch):
    scene, res = dp
    with pytest.raises(ModelError, match="unknown point 'tip' to trace.*use one of O, P1"):
        anim.motion(res, scene.spec.model, trace=["tip"])
    monkeypatch.setattr(anim.shutil, "which", lambda name: None)
    with pytest.raises(ModelgenError, match="needs ffmpeg on PATH.*write a .gif"):
        scene.animate(res, tmp_path / "dp.mp4", max_frames=5)


class _Scripts(HTMLParser):
    def __init__(self):
        super().__init__()
        self.scripts, self._open = [], None

    def handle_starttag(self, tag, attrs):
        if tag == "script":
            self._open = dict(attrs)
            self.scripts.append([self._open, ""])

    def handle_data(self, data):
        if self._open is not None:
            self.scripts[-1][1] += data

    def handle_endtag(self, tag):
        if tag == "script":
            self._open = None


def test_hostile_names_cannot_break_out_of_the_viewer_script(tmp_path):
    path = anim.write_html(_hostile_motion(), tmp_path / "hostile.html")
    text = path.read_text()
    parser = _Scripts()
    parser.feed(text)
    assert len(parser.scripts) == 2                  # the data and the renderer, nothing else
    (attrs, data), (_, code) = parser.scripts
    assert attrs == {"type": "application/json", "id": "motion-data"}
    assert "<" not in data and "alert" not in code
    decoded = json.loads(data)
    assert decoded["name"] == HOSTILE and decoded["points"][1] == HOSTILE + "&<!--"
    assert text.count("<script") == 2 and "&lt;/script&gt;" in text     # the title, escaped
    assert not re.search(r"https?://", text)         # nothing fetched at view time


def test_the_viewer_is_self_contained_and_carries_the_run(dp, tmp_path):
    scene, res = dp
    path = scene.animate(res, tmp_path / "dp.html", max_frames=30)
    text = path.read_text()
    assert not re.search(r"(src|href)\s*=", text)    # no external script, style or image
    parser = _Scripts()
    parser.feed(text)
    data = json.loads(parser.scripts[0][1])
    assert len(data["t"]) == 30 and data["points"] == ["O", "P1", "G1", "G2", "A"]
    assert np.allclose(np.array(data["positions"])[:, 1, :2],
                       np.column_stack([np.cos(res["q1"]), np.sin(res["q1"])])[
                           np.searchsorted(res.t, data["t"])], atol=1e-5)


def test_simulate_cli_animate_writes_gif_and_html(build_root, tmp_path, capsys):
    from PIL import Image
    from modelgen.cli import main
    status = main(["simulate", str(SCENES / "dp_free.yaml"), "-o", str(tmp_path),
                   "--build-dir", str(build_root / "dp_free"), "--t-end", "0.4",
                   "--no-plot", "--animate", "--trace", "P1", "--trace", "G2"])
    assert status == 0
    out = capsys.readouterr().out
    assert f"wrote {tmp_path / 'dp_free.gif'}" in out and "dp_free.html" in out
    with Image.open(tmp_path / "dp_free.gif") as im:
        assert im.n_frames == 11                     # 0.4 s at 25 frames per second
    assert '"trace": [1, 3]' in (tmp_path / "dp_free.html").read_text()


def _browser():
    """Playwright driving the system's Chromium, or a reason to skip."""
    if not (os.path.isfile(CHROMIUM) and os.access(CHROMIUM, os.X_OK)):
        pytest.skip(f"no Chromium at {CHROMIUM} (apt-get install chromium; or set "
                    f"MODELGEN_CHROMIUM)")
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        pytest.skip("the playwright package is missing (pip install playwright; no browser "
                    "download needed)")
    return sync_playwright


_SNAPSHOT = """() => {
  const c = document.getElementById("view");
  const d = c.getContext("2d").getImageData(0, 0, c.width, c.height).data;
  let ink = 0;
  for (let i = 0; i < d.length; i += 4) {
    if (d[i] < 250 || d[i + 1] < 250 || d[i + 2] < 250) { ink++; }
  }
  return {url: c.toDataURL(), ink: ink, time: document.getElementById("time").textContent};
}"""


def test_viewer_plays_in_headless_chromium_without_errors(dp, tmp_path):
    sync_playwright = _browser()
    scene, res = dp
    viewer = scene.animate(res, tmp_path / "dp.html")
    hostile = anim.write_html(_hostile_motion(), tmp_path / "hostile.html")
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": 900, "height": 900})
            problems, requests = [], []
            page.on("console", lambda msg: msg.type == "error" and problems.append(msg.text))
            page.on("pageerror", lambda exc: problems.append(str(exc)))
            page.on("dialog", lambda dialog: (problems.append("dialog " + dialog.message),
                                              dialog.dismiss()))
            page.on("request", lambda req: requests.append(req.url))
            page.goto(viewer.as_uri())
            page.wait_for_timeout(300)
            first = page.evaluate(_SNAPSHOT)
            page.wait_for_timeout(700)
            second = page.evaluate(_SNAPSHOT)
            assert first["ink"] > 500 and second["ink"] > 500       # not blank
            assert first["url"] != second["url"] and first["time"] != second["time"]
            page.click("#play")                                     # pause: the picture holds
            page.wait_for_timeout(100)
            held = page.evaluate(_SNAPSHOT)
            page.wait_for_timeout(400)
            assert page.evaluate(_SNAPSHOT)["url"] == held["url"]
            page.mouse.move(450, 300)                               # drag rotates the view
            page.mouse.down()
            page.mouse.move(550, 340, steps=5)
            page.mouse.up()
            assert page.evaluate(_SNAPSHOT)["url"] != held["url"]
            page.goto(hostile.as_uri())
            page.wait_for_timeout(300)
            assert page.title().startswith(HOSTILE)
            assert page.evaluate(_SNAPSHOT)["ink"] > 100
            assert not problems, problems
            assert all(url.startswith("file://") for url in requests), requests
        finally:
            browser.close()


# -- whole files or none ---------------------------------------------------------------

def _half_then_full_disk(real):
    """A writer that writes half of its output, then finds the disk full."""
    import errno

    def write(target, data, *args, **kwargs):
        real(target, data[:len(data) // 2], *args, **kwargs)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    return write


@pytest.mark.parametrize("suffix", [".gif", ".mp4", ".html"])
def test_an_animation_that_fails_midway_leaves_the_previous_file_alone(tmp_path, monkeypatch,
                                                                       suffix):
    """Animations appear only once complete (written beside, then renamed): a writer
    failing midway leaves no cut file under the final name, and an earlier file
    there is kept as it was."""
    from pathlib import Path

    import matplotlib.animation
    from PIL import Image
    path = tmp_path / f"run{suffix}"
    path.write_bytes(b"the previous complete animation")
    if suffix == ".gif":
        def save(image, fp, *args, **kwargs):
            Path(fp).write_bytes(b"GIF89a half a movie")
            raise OSError(28, "No space left on device")
        monkeypatch.setattr(Image.Image, "save", save)
    elif suffix == ".mp4":              # ffmpeg stood in for: one frame, then a failure
        class Writer:
            def __init__(self, **options):
                pass

            def saving(self, fig, outfile, dpi):
                self.outfile = Path(outfile)
                return contextlib.nullcontext()

            def grab_frame(self):
                self.outfile.write_bytes(b"\x00\x00\x00\x18ftypmp42 one frame")
                raise RuntimeError("ffmpeg died")
        monkeypatch.setattr(anim.shutil, "which", lambda name: "/usr/bin/ffmpeg")
        monkeypatch.setattr(matplotlib.animation, "FFMpegWriter", Writer)
    else:
        monkeypatch.setattr(Path, "write_text", _half_then_full_disk(Path.write_text))
    with pytest.raises((OSError, RuntimeError)):
        if suffix == ".html":
            anim.write_html(_hostile_motion(), path)
        else:
            anim.write_movie(_hostile_motion(), path)
    assert path.read_bytes() == b"the previous complete animation"
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_an_animation_written_whole_replaces_the_previous_file(tmp_path):
    from PIL import Image
    path = tmp_path / "run.gif"
    path.write_bytes(b"the previous animation")
    assert anim.write_movie(_hostile_motion(), path) == path
    with Image.open(path) as im:
        assert im.n_frames == 11
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]
