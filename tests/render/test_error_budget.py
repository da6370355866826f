"""The error budget (raycore/adaptive.py, render.max_error): checked on an
analytic image whose true pixel values are known (the area of a disc inside
each pixel), and through the renderer on a flat-shaded plane and a scene."""
import sys

import numpy as np
import pytest

from anim.render.renderer import SceneRenderer
from anim.render.settings import config_of, shading_of
from anim.scene import AnimatedScene
from raycore.adaptive import refine
from raycore.geometry.sampling import ROUND_TOTALS, budget_offsets, sample_offset, sample_offsets, sobol_point
from scene_files import scene_with

W, H = 48, 40
DISC = (21.3, 18.7, 11.2)                  # centre x, y and radius in pixels
GREY = np.array([0.7, 0.5, 0.3], np.float32)


def inside(x, y):
    cx, cy, r = DISC
    return (x - cx) ** 2 + (y - cy) ** 2 <= r * r


def disc_pass(calls):
    """trace_passes of the analytic image: a grey disc on black, one sample
    per pixel at each of the given sub-pixel offsets."""
    def trace_passes(pixels, offsets, aov=True):
        out = []
        for offset in offsets:
            calls.append(pixels.size)
            x, y = pixels % W + offset[0], pixels // W + offset[1]
            hit = pixels[inside(x, y)]
            rgb = np.repeat(GREY[:, None], hit.size, axis=1)
            out.append((hit.astype(np.int32), rgb, np.ones(hit.size, np.float32)))
        return out
    return trace_passes


def centre_image():
    """The 1-spp image (pixel centres) of the disc."""
    p = np.arange(W * H)
    hit = inside(p % W + 0.5, p // W + 0.5)
    rgba = np.zeros((W * H, 4), np.float32)
    rgba[hit, :3] = GREY
    rgba[hit, 3] = 1
    z = np.where(hit, 1.0, np.inf).astype(np.float32)
    return rgba, z


def true_coverage(n=64):
    """Each pixel's disc area, by an n x n midpoint grid."""
    g = (np.arange(n) + 0.5) / n
    p = np.arange(W * H)
    x = (p % W)[:, None, None] + g[None, None, :]
    y = (p // W)[:, None, None] + g[None, :, None]
    return inside(x, y).mean(axis=(1, 2))


@pytest.mark.parametrize("max_error, cap", [(0.05, 16), (0.01, 64), (0.002, 256)])
def test_no_pixel_above_the_budget_stops_short_of_the_cap(max_error, cap):
    rgba, z = centre_image()
    contrast_flagged = None
    calls = []
    samples, estimate = refine(rgba, z, W, H, np.zeros(3, np.float32), max_error, cap, disc_pass(calls))
    full = budget_offsets(cap)[1][-1]                              # the cap's plain set and the samples before
    assert np.all((samples == full) | (estimate <= max_error))    # the guarantee
    assert np.all(samples[estimate > max_error] == full)
    # a pixel the disc's edge crosses is refined; one far inside or outside is not
    cov = true_coverage()
    edge = (cov > 0.02) & (cov < 0.98)
    assert np.all(samples[edge] > 1)
    contrast_flagged = samples > 1
    assert contrast_flagged.sum() < 0.5 * W * H
    # the rays spent are those of the refined pixels, and the ring outside the frame
    assert sum(calls) == int((samples - 1).sum()) + 2 * (W + H) + 4
    assert set(np.unique(samples)) <= {1} | set(budget_offsets(cap)[1])
    # the image is close to the truth: alpha is the disc's area in each pixel
    err = np.abs(rgba[:, 3] - cov)
    assert np.sqrt(np.mean(err ** 2)) < max_error
    assert np.quantile(err, 0.99) < 6 * max_error, np.sort(err)[-10:]
    np.testing.assert_allclose(rgba[:, :3], rgba[:, 3:4] * GREY, atol=1e-6)


def test_an_object_entering_through_the_frame_edge_is_refined(monkeypatch):
    """Issue 20: a disc rising through the bottom edge, its top 0.3 px
    above the frame's edge, so no pixel centre of the last row touches it:
    with only the frame's own neighbours every contrast was 0 there and the
    pixels kept an error of ~0.3 under every budget. The ring of samples
    just outside the frame sees it."""
    monkeypatch.setattr(sys.modules[__name__], "DISC", (24.2, H + 20.0, 20.3))
    rgba, z = centre_image()
    assert rgba[:, 3].max() == 0, "no centre may see the disc"
    cov = true_coverage(128)
    assert cov.max() > 0.25
    calls = []
    samples, estimate = refine(rgba, z, W, H, np.zeros(3, np.float32), 0.01, 64, disc_pass(calls))
    touched = cov > 0.02
    assert np.all(samples[touched] > 1)
    assert np.abs(rgba[:, 3] - cov).max() < 0.03
    assert sum(calls) - int((samples - 1).sum()) == 2 * (W + H) + 4      # the ring's rays


@pytest.mark.parametrize("cap", [2, 4, 8, 16, 24, 64])
def test_a_pixel_refined_to_the_cap_is_as_good_as_plain_spp(cap):
    """Issue 20: cutting a nested round short at the cap (the centre, a pair
    and an unpaired point at cap 4) made a capped pixel worse than plain
    `--spp cap`. The disc's edge pixels, refined with a budget no pixel can
    meet, against the same pixels at plain spp: the plan ends with the
    plain set, so the error is no larger (old plan: 1.15-1.35x)."""
    rgba, z = centre_image()
    samples, _ = refine(rgba, z, W, H, np.zeros(3, np.float32), 1e-9, cap, disc_pass([]))
    cov = true_coverage(128)
    edge = samples > 1
    assert edge.sum() > 50
    plain = np.zeros(W * H)
    for jx, jy in sample_offsets(cap):
        p = np.arange(W * H)
        plain += inside(p % W + jx, p // W + jy)
    plain /= cap
    rms = lambda a: float(np.sqrt(np.mean((a[edge] - cov[edge]) ** 2)))
    assert rms(rgba[:, 3]) <= 1.02 * rms(plain), (rms(rgba[:, 3]), rms(plain))
    # and it cost at most 1.25x the plain rays on those pixels
    assert samples.max() <= 1.25 * cap + 1


def test_the_budget_plan_nests_and_ends_with_the_plain_set():
    for cap in (2, 3, 4, 7, 16, 28, 64, 100, 256, 1024):
        offsets, totals = budget_offsets(cap)
        assert totals[-1] == len(offsets) and list(totals) == sorted(set(totals))
        d = totals[-1] - cap
        assert offsets[:d] == [sample_offset(i) for i in range(d)] and offsets[d:] == sample_offsets(cap)
        assert 4 * d <= max(cap, 4) and all(t in ROUND_TOTALS for t in totals[:-1])


def test_a_tighter_budget_costs_more_rays_and_gives_less_error():
    cov = true_coverage()
    rows = []
    for e in (0.05, 0.02, 0.005):
        rgba, z = centre_image()
        samples, _ = refine(rgba, z, W, H, np.zeros(3, np.float32), e, 256, disc_pass([]))
        rows.append((int(samples.sum()), float(np.sqrt(np.mean((rgba[:, 3] - cov) ** 2)))))
    assert rows[0][0] < rows[1][0] < rows[2][0]
    assert rows[0][1] > rows[1][1] > rows[2][1]
    # and far fewer rays than uniform sampling at the cap
    assert rows[-1][0] < 0.25 * 256 * W * H


def test_a_flat_image_gets_one_sample_everywhere_and_no_pass():
    rgba = np.tile(np.array([0.2, 0.3, 0.4, 1.0], np.float32), (W * H, 1))
    z = np.ones(W * H, np.float32)
    calls = []

    def flat_pass(pixels, offsets, aov=True):          # the colour everywhere, the ring included
        calls.append(pixels.size * len(offsets))
        return [(pixels.astype(np.int32), np.repeat(rgba[:1, :3].T, pixels.size, axis=1),
                 np.ones(pixels.size, np.float32))] * len(offsets)
    samples, estimate = refine(rgba, z, W, H, np.zeros(3, np.float32), 0.001, 64, flat_pass)
    assert sum(calls) == 2 * (W + H) + 4 and np.all(samples == 1) and np.all(estimate == 0)


def test_the_sequence_points_form_nets_and_the_samples_are_symmetric():
    pts = np.array([sobol_point(i) for i in range(512)])
    assert tuple(pts[0]) == (0.5, 0.5)
    for k in range(1, 9):
        n = 2 ** k
        for block in (pts[:n], pts[n:2 * n]):
            # one point in each of the n strips across and along the square
            assert sorted(np.floor(block[:, 0] * n).astype(int)) == list(range(n))
            assert sorted(np.floor(block[:, 1] * n).astype(int)) == list(range(n))
    for total in ROUND_TOTALS[:6]:
        offsets = np.array([sample_offset(i) for i in range(total)])
        assert tuple(offsets[0]) == (0.5, 0.5)
        np.testing.assert_allclose(offsets.mean(axis=0), 0.5, atol=1e-12)   # no shift of the image
        assert np.all((offsets >= 0) & (offsets <= 1)) and len(np.unique(offsets, axis=0)) == total
        # the right half's points (the centre on its edge) are one net
        right = offsets[offsets[:, 0] >= 0.5]
        n = (total + 1) // 2
        assert sorted(np.floor((right[:, 0] - 0.5) * 2 * n).astype(int)) == list(range(n))


@pytest.mark.parametrize("offsets", [sample_offsets(16), [sample_offset(i) for i in range(15)]],
                         ids=["hammersley", "budget"])
def test_stratified_samples_are_unbiased_on_half_covered_pixels(offsets):
    """A straight edge through the pixel's centre at a random angle covers
    half of it: the fraction of the samples it covers averages to 1/2 over
    the angles, and each estimate is within a few strata of it. (A sample on
    the edge, such as the centre, counts one half: the edge passes through
    a point of zero area.)"""
    pts = np.asarray(offsets) - 0.5
    angles = np.random.default_rng(3).uniform(0, 2 * np.pi, 4000)
    normal = np.stack([np.cos(angles), np.sin(angles)], axis=1)
    covered = ((np.sign(pts @ normal.T) + 1) / 2).mean(axis=0)
    assert abs(covered.mean() - 0.5) <= 3 * covered.std() / np.sqrt(len(angles)) + 1e-12
    assert np.abs(covered - 0.5).max() <= 3 / len(pts)


FLAT = ("  - {name: floor, mesh: floor.obj, transform: {scale: {keys: [[0, 40, 1, 40]]}}}\n")
FLAT_CAMERA = "camera: {eye: [0, 6, 0.001], look_at: [0, 0, 0], up: [0, 0, -1], fov: 30}"


def render(path, **overrides):
    scene = AnimatedScene(path)
    cfg = config_of(scene, width=40, height=32, aovs=(), **overrides)
    return SceneRenderer(scene, cfg, shading_of(scene)).render(0.0)[1]


def test_a_flat_shaded_plane_gets_one_sample_per_pixel(tmp_path):
    """Straight down on an untextured floor lit by a directional light: every
    pixel the same colour, so the budget adds no sample and the frame is
    the 1-spp frame, bit for bit."""
    path = scene_with(tmp_path, FLAT, camera_yaml=FLAT_CAMERA)
    text = path.read_text().replace("lights: [{type: point, position: [3, 5, 4], intensity: 30}]",
                                    "lights: [{type: directional, direction: [0.2, -1, 0.1], intensity: 2}]")
    path.write_text(text.replace("materials:", "materials:") + "")
    one = render(path)
    assert np.ptp(one.rgba[..., :3]) < 1e-6, "the test needs a flat image"
    budget = render(path, max_error=0.001)
    assert np.all(budget.samples == 1) and budget.counters["rays"] == 40 * 32 + 2 * (40 + 32) + 4
    np.testing.assert_array_equal(budget.rgba, one.rgba)
    np.testing.assert_array_equal(budget.z, one.z)


def test_the_budget_in_a_frame_refines_edges_and_counts_its_rays(tmp_path):
    path = scene_with(tmp_path, "  - {name: floor, mesh: floor.obj}\n  - {name: ball, mesh: ball.obj}\n")
    ref = render(path, spp=256)
    one = render(path)
    budget = render(path, max_error=0.01, spp=64)
    assert budget.samples.max() > 1 and (budget.samples == 1).mean() > 0.3
    err = lambda r: float(np.sqrt(np.mean((r.rgba - ref.rgba) ** 2)))
    assert err(budget) < 0.5 * err(one)
    c = budget.counters
    assert c["rays"] < 64 * 40 * 32 and c["rays_left_out"] == 64 * 40 * 32 - c["rays"] and c["spp_cap"] == 64
    assert c["rays"] >= budget.samples.sum()          # whole 4x4 blocks are traced


PLATE = ("  - {name: floor, mesh: floor.obj, transform: {scale: {keys: [[0, 4, 1, 4]]}}}\n"
         "  - {name: plate, mesh: floor.obj, transform: {translation: {keys: [[0, 0.1, 0.8, 0.05]]},"
         " rotation: {keys: [[0, 0.9962, 0, 0.0872, 0]]}, scale: {keys: [[0, 0.4, 1, 0.3]]}}}\n")


@pytest.mark.parametrize("spp", [4, 16])
def test_a_budget_capped_by_spp_is_no_worse_than_plain_spp(tmp_path, spp):
    """Issue 20's scene: a plate over a floor, a point light, a budget no
    edge can meet. Before: --spp 4 --max-error 0.001 had 1.4x the RMSE of
    --spp 4 alone (the cap cut a round short)."""
    path = scene_with(tmp_path, PLATE, camera_yaml="camera: {eye: [1.5, 2.5, 3.5], look_at: [0, 0.3, 0], fov: 40}")
    ref = render(path, spp=256).rgba
    err = lambda r: float(np.sqrt(np.mean((r.rgba - ref) ** 2)))
    plain, budget = render(path, spp=spp), render(path, spp=spp, max_error=0.001)
    assert budget.samples.max() > 1
    assert err(budget) <= 1.02 * err(plain), (err(budget), err(plain))
