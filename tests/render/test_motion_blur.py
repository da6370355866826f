"""Motion blur and depth of field (raycore/geometry/shutter_lens.py, PassScene in
raycore/frame.py) against closed forms: an edge crossing the image at
constant speed, whose every pixel's alpha is the share of pixel area and
shutter time it covers; a point off the focus plane, whose image is the
thin lens's circle of confusion; and the unblurred frame, unchanged."""
import numpy as np
import pytest

from anim.render.renderer import SceneRenderer
from anim.render.settings import config_of, shading_of
from anim.scene import AnimatedScene
from raycore.geometry.shutter_lens import budget_times_lens, concentric_disc, plain_times_lens
from anim.builtin.authoring import write_obj

W, H = 64, 8                 # the image; one pixel is one scene unit on the plane z = 0
SPEED = 20.0                 # the edge's speed: pixels per frame interval
FPS = 1.0
FRAME = 2                    # rendered at t = 2 s: the edge then at x = 2 * SPEED + X0
X0 = -2 * SPEED              # so that at the frame time the edge is at the image's centre


def edge_scene(tmp_path, blur="", camera_extra="", spp=1, max_error=0.0, lights=False):
    """A black background and, in the plane z = 0, a large quad whose right
    edge moves along +x at SPEED pixels per frame; the camera looks straight
    at the plane from z = 10 with one scene unit per pixel."""
    write_obj(tmp_path / "quad.obj", np.array([[-1000, -100, 0], [0, -100, 0], [0, 100, 0], [-1000, 100, 0]]),
              np.array([[0, 1, 2], [0, 2, 3]]))
    fov = float(np.degrees(2 * np.arctan(H / 20)))  # 2 h / H * 10 = 1 unit per pixel
    light = "lights: [{type: point, position: [0, 0, 5], intensity: 10}]" if lights else "lights: []"
    (tmp_path / "s.yaml").write_text(f"""version: 1
frames: {{start: 0, end: 4, fps: {FPS}}}
output: {{path: out/f_##.exr, resolution: [{W}, {H}]}}
camera: {{eye: [0, 0, 10], look_at: [0, 0, 0], fov: {fov!r}{camera_extra}}}
render: {{spp: {spp}, max_error: {max_error}, packet: 8{blur}}}
{light}
objects:
  - name: quad
    mesh: quad.obj
    transform:
      translation: {{interpolation: linear, keys: [[0, {X0}, 0, 0], [4, {X0 + 4 * SPEED}, 0, 0]]}}
""")
    return tmp_path / "s.yaml"


def render(path, frame=FRAME):
    scene = AnimatedScene(path)
    cfg = config_of(scene)
    _, result = SceneRenderer(scene, cfg, shading_of(scene)).render(scene.time_of(frame))
    return result


def exact_alpha(shutter, opens, speed=SPEED):
    """Each column's alpha: the mean over the pixel's width and the shutter of
    whether the quad covers the point. The edge is at image x
    e(s) = W/2 + SPEED s, s in frame intervals from the frame time, s over
    [opens, opens + shutter] (opens = -shutter/2 centred, 0 start, -shutter
    end): the covered part of pixel [x, x + 1) is clamp(e(s) - x, 0, 1),
    averaged here over 200,000 shutter times (an error below 1e-5)."""
    s = opens + shutter * (np.arange(200_000) + 0.5) / 200_000
    e = W / 2 + speed * s
    return np.array([np.clip(e - x, 0.0, 1.0).mean() for x in range(W)])


def test_the_sample_patterns_are_stratified_in_time_and_on_the_lens():
    """Plain spp n: every one of the n shutter strata and lens-x, lens-y
    strata once (checked before the disc map through its inverse on the
    axes: the concentric map keeps x's sign and order along a row)."""
    for n in (2, 7, 16, 64):
        tl = np.array(plain_times_lens(n))
        assert sorted(np.floor(tl[:, 0] * n).astype(int)) == list(range(n))
        assert np.all(np.hypot(tl[:, 1], tl[:, 2]) <= 1 + 1e-12)
    assert plain_times_lens(1) == ((0.5, 0.0, 0.0),)
    # at a pixel centre an edge covering it for the share s of the shutter
    # (from time 1 - s on) is seen by a share of the passes within 1/n of s
    for n in (3, 16, 100):
        times = np.array(plain_times_lens(n))[:, 0]
        for share in np.linspace(0, 1, 997):
            assert abs(np.mean(times >= 1 - share) - share) <= 1 / n + 1e-12
    # nested samples: the first is the shutter's middle and the lens centre (the 1-spp image)
    tl = budget_times_lens(64)
    assert tl[0] == (0.5, 0.0, 0.0) and len(tl) == 15 + 64
    # the concentric map: area kept (uniform in, uniform out: mean r^2 = 1/2)
    g = (np.arange(200) + 0.5) / 200
    pts = np.array([concentric_disc(a, b) for a in g for b in g])
    assert abs((pts ** 2).sum(axis=1).mean() - 0.5) < 1e-3
    assert abs(pts.mean(axis=0)).max() < 1e-9


@pytest.mark.parametrize("position,opens", [("center", -0.25), ("start", 0.0), ("end", -0.5)])
def test_a_moving_edge_covers_each_pixel_for_its_share_of_the_shutter(tmp_path, position, opens):
    """Shutter 0.5 (the edge sweeps 10 pixels): alpha matches the closed form
    within the sampling error of 64 passes, and start / end move the blur
    by half the shutter (5 pixels) to either side of the centred one."""
    shutter = 0.5
    path = edge_scene(tmp_path, f", motion_blur: {{shutter: {shutter}, position: {position}}}", spp=64)
    alpha = render(path).rgba[:, :, 3].astype(np.float64)
    assert np.all(alpha == alpha[0])                     # the edge is vertical: rows agree
    exact = exact_alpha(shutter, opens)
    assert np.abs(alpha[0] - exact).max() < 0.03, np.round(np.c_[alpha[0], exact][25:50], 3)
    # where alpha crosses 1/2: the edge's position at the shutter's middle
    middle = W / 2 + SPEED * (opens + shutter / 2)
    crossing = np.interp(0.5, alpha[0][::-1], (np.arange(W) + 0.5)[::-1])
    assert abs(crossing - middle) < 0.1


def test_motion_blur_error_falls_as_the_passes_stratify_time(tmp_path):
    """RMSE of the blurred columns against the closed form for 4 ... 256
    passes: the log-log slope is that of stratified sampling (about -1;
    random times would give -1/2)."""
    shutter, counts, errors = 0.5, (4, 16, 64, 256), []
    exact = exact_alpha(shutter, -0.25)
    for spp in counts:
        path = edge_scene(tmp_path, f", motion_blur: {{shutter: {shutter}}}", spp=spp)
        alpha = render(path).rgba[0, :, 3].astype(np.float64)
        errors.append(np.sqrt(np.mean((alpha - exact)[20:45] ** 2)))
    slope = np.polyfit(np.log(counts), np.log(errors), 1)[0]
    assert slope < -0.68, (errors, slope)


def test_an_error_budget_refines_the_blurred_pixels_at_their_own_times(tmp_path):
    """max_error with motion blur: every pixel takes the first nested round
    (7 samples at 7 shutter times: the 1-spp image is one instant and shows
    no blur), the passes then go to the blurred columns, each at its own
    shutter time, and those match the closed form. What no first-round
    sample of a pixel or its neighbours sees stays unseen, as in the
    budget's spatial estimate: the edge covering a pixel for only the
    shutter's first 5 % (before the earliest first-round time, 1/6)."""
    path = edge_scene(tmp_path, ", motion_blur: {shutter: 0.5}", max_error=0.01)
    result = render(path)
    exact = exact_alpha(0.5, -0.25)
    alpha = result.rgba[0, :, 3].astype(np.float64)
    seen = (exact > 1 / 6) & (exact < 5 / 6)
    assert seen.sum() >= 6
    assert np.abs(alpha - exact)[seen].max() < 0.02, np.round(np.c_[alpha, exact][25:40], 3)
    assert np.abs(alpha - exact).max() <= 1 / 6
    spp = result.samples.reshape(H, W)[0]
    assert spp[seen].min() > 7 and spp[:15].max() == 7 and spp[50:].max() == 7
    assert result.counters["time_samples"] > 7


def test_a_point_off_the_focus_plane_blurs_into_the_circle_of_confusion(tmp_path):
    """A small sphere at distance d with the focus at F: the lens spreads its
    image over a disc of radius A |d - F| / d on the focus plane, in pixels
    that radius over the pixel size there, 2 h F / H. Measured from the
    alpha image's second moment (a uniform disc of radius R has E r^2 = R^2/2,
    plus the sphere's own image)."""
    from anim.builtin.shapes import icosphere
    v, f = icosphere(3, 0.05)
    write_obj(tmp_path / "dot.obj", v, f)
    d, focus, aperture, res, fov = 6.0, 10.0, 0.4, 64, 20.0
    (tmp_path / "s.yaml").write_text(f"""version: 1
output: {{path: out/f.exr, resolution: [{res}, {res}]}}
camera: {{eye: [0, 0, {d}], look_at: [0, 0, 0], fov: {fov}, aperture_radius: {aperture}, focus_distance: {focus}}}
render: {{spp: 256, packet: 8}}
lights: []
objects:
  - {{name: dot, mesh: dot.obj}}
""")
    pixel = 2 * np.tan(np.radians(fov) / 2) * focus / res      # pixel size on the focus plane
    expected = aperture * abs(d - focus) / d / pixel
    alpha = render(tmp_path / "s.yaml", 0).rgba[:, :, 3].astype(np.float64)
    y, x = np.mgrid[0:res, 0:res] + 0.5
    m = alpha.sum()
    cx, cy = (alpha * x).sum() / m, (alpha * y).sum() / m
    assert abs(cx - res / 2) < 0.1 and abs(cy - res / 2) < 0.1
    second = (alpha * ((x - cx) ** 2 + (y - cy) ** 2)).sum() / m
    own = (0.05 / d) / (2 * np.tan(np.radians(fov) / 2) / res)    # the sphere's image radius, pinhole
    measured = np.sqrt(2 * (second - own ** 2 / 2))
    assert abs(measured - expected) < 0.03 * expected, (measured, expected)
    # the disc's area holds the sphere's: alpha sums to its pinhole image
    assert abs(m - np.pi * own ** 2) < 0.05 * np.pi * own ** 2


def test_depth_is_along_the_view_axis_through_the_lens(tmp_path):
    """Z of a plane facing the camera is its distance, whatever lens point a
    pass took (the lens moves the eye within the plane z = 10)."""
    path = edge_scene(tmp_path, "", camera_extra=", aperture_radius: 0.5, focus_distance: 4", spp=16)
    z = render(path).z
    covered = np.isfinite(z)
    assert covered.sum() > W * H / 4
    assert np.abs(z[covered] - 10.0).max() < 1e-5


def test_without_blur_or_lens_the_frame_is_unchanged(tmp_path):
    """shutter 0 and aperture 0 written out give the frame of a file without
    them, bit for bit; so does a shutter on a scene in which nothing moves
    (no rebuild per pass: the structures are built once)."""
    plain = render(edge_scene(tmp_path, "", spp=4, lights=True))
    off = render(edge_scene(tmp_path, ", motion_blur: {shutter: 0}", ", aperture_radius: 0", spp=4, lights=True))
    assert np.array_equal(plain.rgba, off.rgba) and np.array_equal(plain.z, off.z)
    assert "time_samples" not in off.counters and off.counters["builds"] == 1
    blurred = render(edge_scene(tmp_path, ", motion_blur: {shutter: 0.5}", spp=4, lights=True))
    assert blurred.counters["builds"] == 4 and blurred.counters["time_samples"] == 4
    assert not np.array_equal(plain.rgba, blurred.rgba)


def test_a_shutter_over_a_held_still_object_builds_once(tmp_path):
    """The quad's keys end at t = 4: at frame 4 with a shutter that opens
    there (position start) it is held still, and the frame builds its
    structures once although every pass takes its own time."""
    path = edge_scene(tmp_path, ", motion_blur: {shutter: 0.5, position: start}", spp=8)
    scene = AnimatedScene(path)
    renderer = SceneRenderer(scene, config_of(scene), shading_of(scene))
    _, still = renderer.render(scene.time_of(4))
    assert still.counters["builds"] == 1 and still.counters["time_samples"] == 8
    _, moving = renderer.render(scene.time_of(2))
    assert moving.counters["builds"] == 8


def test_a_moving_camera_blurs_a_still_scene_without_rebuilding_it(tmp_path):
    """The quad held still (edge at x = 0) and the camera moving along +x at
    SPEED pixels per frame: the edge sweeps the image the other way, by the
    same closed form, and the structures are built once per frame (only
    the camera moves within the shutter)."""
    write_obj(tmp_path / "quad.obj", np.array([[-1000, -100, 0], [0, -100, 0], [0, 100, 0], [-1000, 100, 0]]),
              np.array([[0, 1, 2], [0, 2, 3]]))
    fov = float(np.degrees(2 * np.arctan(H / 20)))
    keys = ", ".join(f"{{t: {t}, eye: [{x}, 0, 10], look_at: [{x}, 0, 0], fov: {fov!r}}}"
                     for t, x in ((0, X0), (4, X0 + 4 * SPEED)))
    (tmp_path / "s.yaml").write_text(f"""version: 1
frames: {{start: 0, end: 4, fps: {FPS}}}
output: {{path: out/f_##.exr, resolution: [{W}, {H}]}}
camera: {{interpolation: linear, keys: [{keys}]}}
render: {{spp: 64, packet: 8, motion_blur: {{shutter: 0.5}}}}
lights: []
objects: [{{name: quad, mesh: quad.obj}}]
""")
    result = render(tmp_path / "s.yaml")
    alpha = result.rgba[0, :, 3].astype(np.float64)
    assert np.abs(alpha - exact_alpha(0.5, -0.25, -SPEED)).max() < 0.03
    assert result.counters["builds"] == 1 and result.counters["time_samples"] == 64


def test_an_object_held_still_within_the_shutter_is_not_placed_per_pass(tmp_path, monkeypatch):
    """A tube whose vertex keys end at t = 1 (clamped) beside the moving
    quad: at frame 2 the shutter spans 1.75..2.25 s, the tube cannot move
    there, so it keeps the frame time's placement, and only the quad is
    placed at each pass's time; its pixels are those of an unblurred frame."""
    from anim.scene import SceneObject
    from scene_files import DEMO
    import shutil
    for f in ("tube_000.obj", "tube_001.obj"):
        shutil.copy(DEMO / f, tmp_path / f)
    path = edge_scene(tmp_path, ", motion_blur: {shutter: 0.5}", spp=8)
    text = path.read_text() + """  - name: tube
    keyframes: [{t: 0, mesh: tube_000.obj}, {t: 1, mesh: tube_001.obj}]
"""
    path.write_text(text)
    scene = AnimatedScene(path)
    tube = scene.objects[1]
    assert tube.held_over(1.75, 2.25) and not tube.held_over(0.75, 1.25)
    assert not scene.objects[0].held_over(1.75, 2.25)
    placed = []
    original = SceneObject.place
    monkeypatch.setattr(SceneObject, "place", lambda self, t, out: (placed.append((self.name, t)),
                                                                    original(self, t, out)))
    renderer = SceneRenderer(scene, config_of(scene), shading_of(scene))
    renderer.render(scene.time_of(2))
    assert placed == [("tube", 2.0)]                 # once, at the frame time, not per pass
    placed.clear()
    renderer.render(scene.time_of(1))                 # shutter 0.75..1.25: the tube's last key is inside
    assert len(placed) == 1 + 8


def test_one_pass_of_blur_is_warned_and_more_passes_are_not(tmp_path):
    """Blur or a lens with one pass shows nothing: `check` and `render` say
    so; with --spp above 1 (the command line's, not only the file's) not."""
    from click.testing import CliRunner
    from cli.main import main
    path = edge_scene(tmp_path, ", motion_blur: {shutter: 0.5}")
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 0 and "shows no blur" in res.output and "motion blur: shutter 0.5" in res.output
    args = ["render", str(path), "-o", str(tmp_path / "o"), "--frames", "2:2", "--quiet", "--overwrite"]
    assert "shows no blur" in CliRunner().invoke(main, args).output
    res = CliRunner().invoke(main, args + ["--spp", "4"])
    assert res.exit_code == 0 and "shows no blur" not in res.output


def test_stats_give_the_passes_and_their_rebuild_time(tmp_path):
    """stats.json under motion blur: time and lens samples, passes, builds
    and rebuild ms per pass (the frame's build_ms over its passes)."""
    import json
    from click.testing import CliRunner
    from cli.main import main
    path = edge_scene(tmp_path, ", motion_blur: {shutter: 0.5}", ", aperture_radius: 0.1", spp=8)
    out = tmp_path / "o"
    res = CliRunner().invoke(main, ["render", str(path), "-o", str(out), "--frames", "2:2", "--quiet"])
    assert res.exit_code == 0, res.output
    f = json.loads((out / "stats.json").read_text())["frames"][0]
    assert (f["time_samples"], f["lens_samples"], f["passes"], f["builds"]) == (8, 8, 8, 8)
    assert f["rebuild_ms_per_pass"] == pytest.approx(f["build_ms"] / 8)


@pytest.mark.parametrize("kind", ["shutter", "lens"])
def test_an_error_budget_finds_the_faint_ends_of_a_blur(tmp_path, kind):
    """A 1x1 quad crossing a 96^2 frame under a half-frame shutter (or
    defocused by a thin lens): the faint ends of its blur, where the true
    alpha is 0.004-0.11, are covered for so short a share of the shutter (or
    of the lens) that a pixel's first samples all miss them, while a
    neighbour's later samples hit. Such a pixel is refined again when its
    neighbours show what it missed, so the faint ends come out within a few
    hundredths of a 256-sample reference (they were 0, 0.07-0.09 off), and a
    tighter budget does no worse."""
    from anim.builtin.authoring import write_obj
    write_obj(tmp_path / "quad.obj", np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0]]),
              np.array([[0, 1, 2], [0, 2, 3]]))
    blur, lens = ((", motion_blur: {shutter: 0.5}", "") if kind == "shutter"
                  else ("", ", aperture_radius: 0.3, focus_distance: 6"))
    (tmp_path / "s.yaml").write_text(f"""version: 1
frames: {{start: 0, end: 48, fps: 24}}
output: {{path: out/f_##.exr, resolution: [96, 96]}}
camera: {{eye: [0, 0, 10], look_at: [0, 0, 0], fov: 20{lens}}}
render: {{spp: 64{blur}}}
lights: []
objects:
  - name: quad
    mesh: quad.obj
    transform:
      translation: {{keys: [[0, -24, 0, 0], [2, 24, 0, 0]]}}
""")
    scene = AnimatedScene(tmp_path / "s.yaml")

    def alpha(**overrides):
        cfg = config_of(scene, **overrides)
        return SceneRenderer(scene, cfg, shading_of(scene)).render(scene.time_of(24))[1].rgba[..., 3].astype(float)
    reference = alpha(spp=256)
    faint = (reference > 0.004) & (reference < 0.11)
    assert faint.sum() > 40
    errors = {}
    for budget in (0.05, 0.01):
        err = np.abs(alpha(max_error=budget) - reference)
        errors[budget] = err.max()
        if budget == 0.01:
            assert err[faint].max() < 0.045, err[faint].max()
    assert errors[0.01] <= errors[0.05] + 1e-3, errors
