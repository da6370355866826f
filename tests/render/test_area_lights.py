"""Area lights (anim/area_lights.py): emitters spread over a rectangle or a
sphere, soft shadows, the point light as the zero-size limit, and
convergence of the unshadowed irradiance to the integral over the light."""
import numpy as np
import pytest
from click.testing import CliRunner

from anim.area_lights import emitter_positions, emitter_uv
from anim.scene import AnimatedScene
from cli.main import main
from anim.render.renderer import SceneRenderer
from anim.render.settings import config_of, shading_of
from scene_files import scene_with

FLOOR_AND_BALL = ("  - {name: floor, mesh: floor.obj}\n"
                  "  - {name: ball, mesh: ball.obj, transform: {translation: {keys: [[0, 0, 0.8, 0]]}}}\n")
CAMERA = "camera: {eye: [0, 4, 5], look_at: [0, -0.5, 0], fov: 50}"
POINT = "lights: [{type: point, position: [3, 5, 4], intensity: 30}]"


def render(tmp_path, lights, size=(64, 48), shadows=True):
    path = scene_with(tmp_path, FLOOR_AND_BALL, camera_yaml=CAMERA)
    path.write_text(path.read_text().replace(POINT, lights))
    scene = AnimatedScene(path)
    cfg = config_of(scene, width=size[0], height=size[1], aovs=(), ambient=0.0, shadows=shadows)
    return SceneRenderer(scene, cfg, shading_of(scene)).render(0.0)[1].rgba


def test_a_zero_size_area_light_is_the_point_light(tmp_path):
    """Bit for bit with one emitter (it is the centre); with several, every
    emitter is the same point and only the float sum of their shares
    differs (issue 20: Halton's emitters of a 1e-6 light moved its shadow,
    1e-3 off in 2 pixels)."""
    point = render(tmp_path, "lights: [{type: point, position: [1, 4, 1], intensity: 30}]")
    for shape in ("{corner: [1, 4, 1], edge_u: [0, 0, 0], edge_v: [0, 0, 0]}",
                  "{corner: [0.9, 4, 0.9], edge_u: [0.2, 0, 0], edge_v: [0, 0, 0.2]}",
                  "{center: [1, 4, 1], radius: 0}", "{center: [1, 4, 1], radius: 0.3}"):
        one = render(tmp_path, f"lights: [{{type: area, intensity: 30, samples: 1, {shape[1:-1]}}}]")
        np.testing.assert_array_equal(one, point)
        if "0.2" in shape or "0.3" in shape:
            continue
        for samples in (2, 7, 8):
            area = render(tmp_path, f"lights: [{{type: area, intensity: 30, samples: {samples}, {shape[1:-1]}}}]")
            np.testing.assert_allclose(area, point, rtol=2e-6, atol=1e-7)


def test_an_area_light_casts_soft_shadows(tmp_path):
    """The share of the light that reaches each floor pixel (shadowed over
    unshadowed image, no ambient): 0 or 1 under a point light, in between
    (a penumbra) around the ball's shadow under a 1x1 area light."""
    def visible(lights):
        on, off = (render(tmp_path, lights, (96, 72), shadows) for shadows in (True, False))
        lit = off[..., 0] > 1e-4
        return on[..., 0][lit] / off[..., 0][lit]
    point = visible("lights: [{type: point, position: [1.5, 2.5, 0], intensity: 30}]")
    area = visible("lights: [{type: area, corner: [1, 2.5, -0.5], edge_u: [1, 0, 0], edge_v: [0, 0, 1], "
                   "intensity: 30, samples: 64}]")
    partial = lambda v: int(((v > 0.05) & (v < 0.95)).sum())
    assert partial(point) <= 2 and (point < 0.05).sum() > 20          # a hard shadow
    assert partial(area) > 40, partial(area)                           # a penumbra


def test_unshadowed_irradiance_converges_to_the_integral_over_the_light():
    """The emitter sum of one rectangle light at a point below it, against a
    dense midpoint quadrature of the same isotropic emission: the error
    falls as the emitters grow in number and is below 0.5% at 256."""
    class Rect:
        corner, edge_u, edge_v = (-1.0, 2.0, -0.5), (2.0, 0.0, 0.0), (0.0, 0.0, 1.0)
    x = np.array([0.3, 0.0, 0.2])
    n = np.array([0.0, 1.0, 0.0])

    def irradiance(points):
        to = points - x
        d2 = np.einsum("ij,ij->i", to, to)
        return np.mean(np.maximum(to @ n, 0) / np.sqrt(d2) / d2)
    g = (np.arange(2000) + 0.5) / 2000
    uu, vv = np.meshgrid(g, g)
    dense = np.asarray(Rect.corner) + uu.reshape(-1, 1) * Rect.edge_u + vv.reshape(-1, 1) * Rect.edge_v
    exact = irradiance(dense)
    errors = []
    for samples in (4, 16, 64, 256):
        Rect.samples = samples
        errors.append(abs(irradiance(emitter_positions(Rect)) / exact - 1))
    assert errors[-1] < 5e-3 and errors[-1] < errors[0], errors


def test_emitter_points_and_their_prefixes_spread_over_the_square():
    pts = emitter_uv(64)
    assert np.all((pts > 0) & (pts < 1))
    for n in (2, 8, 16, 64):                    # every prefix that ends a pair has its centroid at the centre
        np.testing.assert_allclose(pts[:n].mean(axis=0), 0.5, atol=1e-12)
    for n in (6, 8, 16, 64):                    # and from 6 on covers every quadrant
        q = np.floor(pts[:n] * 2).astype(int)
        assert len({(a, b) for a, b in q}) == 4, n
    for n, k in ((16, 4), (16, 8), (64, 8), (64, 16)):   # about n / k in every strip, across and along
        for axis in (0, 1):
            counts = np.bincount(np.floor(pts[:n, axis] * k).astype(int), minlength=k)
            assert np.abs(counts - n / k).max() <= 3, (n, k, counts)


class Rect:
    corner, edge_u, edge_v, center, radius = (1.0, 2.0, 3.0), (2.0, 0.0, 0.5), (0.0, 0.0, 1.0), None, None


class Sphere:
    corner = None
    center, radius = (1.0, 2.0, 3.0), 0.5


@pytest.mark.parametrize("shape", [Rect, Sphere])
@pytest.mark.parametrize("samples", [1, 2, 3, 4, 5, 16, 64])
def test_any_number_of_emitters_is_centred_on_the_light(shape, samples):
    """Issue 20: Halton from (1/2, 1/3) put one sample 1/6 of edge_v off the
    rectangle's centre (its shadow moved), one sphere sample on its surface,
    and the centroid of 4 at (0.41, 0.39)."""
    shape.samples = samples
    p = emitter_positions(shape)
    centre = (np.asarray(shape.center) if shape.corner is None else
              np.asarray(shape.corner) + 0.5 * np.add(shape.edge_u, shape.edge_v))
    assert p.shape == (samples, 3)
    np.testing.assert_allclose(p.mean(axis=0), centre, atol=1e-12)
    if samples == 1:
        assert np.all(p[0] == centre)                 # one sample is the point light at the centre
    assert len(np.unique(p, axis=0)) == samples


def test_a_sphere_lights_emitters_lie_on_its_surface():
    Sphere.samples = 64
    p = emitter_positions(Sphere)
    np.testing.assert_allclose(np.linalg.norm(p - Sphere.center, axis=1), 0.5)
    Sphere.samples = 65                              # an odd count: the centre last
    p = emitter_positions(Sphere)
    np.testing.assert_allclose(np.linalg.norm(p[:-1] - Sphere.center, axis=1), 0.5)
    assert np.all(p[-1] == Sphere.center)
    # the first point of each pair covers the lower hemisphere evenly
    z = (p[:-1:2, 2] - Sphere.center[2]) / 0.5
    assert np.all(z <= 0) and abs(z.mean() + 0.5) < 0.02


@pytest.mark.parametrize("light, words", [
    ("{type: area, corner: [0, 1, 0], edge_u: [1, 0, 0]}", ["corner, edge_u, edge_v", "center, radius"]),
    ("{type: area, center: [0, 1, 0], radius: 1, corner: [0, 0, 0], edge_u: [1, 0, 0], edge_v: [0, 0, 1]}",
     ["takes"]),
    ("{type: point, position: [0, 1, 0], samples: 4}", ["samples is for area lights"]),
])
def test_area_light_mistakes_are_named(tmp_path, light, words):
    path = scene_with(tmp_path, FLOOR_AND_BALL)
    path.write_text(path.read_text().replace(POINT, f"lights: [{light}]"))
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2 and "lights.0" in res.output and all(w in res.output for w in words), res.output


def test_light_probes_buy_a_better_image_with_fewer_rays(tmp_path):
    """render.light_probes: the first 16 emitters for every point, the rest
    only where those disagree (the penumbra). 256 emitters probed so cost
    fewer shadow rays than 64 traced everywhere, and come closer to a
    512-emitter reference."""
    path = scene_with(tmp_path, FLOOR_AND_BALL, camera_yaml=CAMERA)

    def frame(samples, probes):
        lights = ("lights: [{type: area, corner: [1, 2.5, -0.5], edge_u: [1, 0, 0], edge_v: [0, 0, 1], "
                  f"intensity: 30, samples: {samples}}}]")
        path.write_text(path.read_text().split("lights:")[0] + lights + "\nobjects:" + path.read_text().split("objects:")[1])
        scene = AnimatedScene(path)
        cfg = config_of(scene, width=96, height=72, aovs=(), light_probes=probes)
        r = SceneRenderer(scene, cfg, shading_of(scene)).render(0.0)[1]
        return r.rgba[..., :3].astype(np.float64), r.counters["shadow_rays"]
    ref, _ = frame(512, 0)
    uniform, rays_uniform = frame(64, 0)
    probed, rays_probed = frame(256, 16)
    rmse = lambda img: np.sqrt(np.mean((img - ref) ** 2))
    assert rays_probed < rays_uniform and rmse(probed) < rmse(uniform), \
        (rays_probed, rays_uniform, rmse(probed), rmse(uniform))
    same, _ = frame(64, 64)                                 # probing all emitters = no probing
    np.testing.assert_array_equal(same, uniform)


# ---- closed forms: a rectangle light above a floor, with and without a straight occluder edge

LIGHT = dict(x0=-1.0, x1=1.0, z0=-1.0, z1=1.0, h=4.0, intensity=30.0)
EDGE_X, EDGE_H = 0.0, 2.0          # occluder: the half-plane x < EDGE_X at height EDGE_H
ALBEDO = 0.8                        # the default material's diffuse


def corner_solid_angle(a, b, h):
    """Solid angle of the rectangle [0, a] x [0, b] at height h, seen from
    the point below its corner (0, 0); signed by a and b."""
    return np.sign(a) * np.sign(b) * np.arctan(np.abs(a * b) / (h * np.sqrt(h * h + a * a + b * b)))


def rect_solid_angle(px, pz, x0, x1, z0, z1, h):
    f = lambda x, z: corner_solid_angle(x - px, z - pz, h)
    return f(x1, z1) - f(x0, z1) - f(x1, z0) + f(x0, z0)


def exact_floor_colour(px, pz, occluded):
    """What a floor point receives from the light made of infinitely many
    isotropic emitters: albedo (I / area) times the solid angle of the part
    of the light it sees (for a horizontal light over a horizontal floor,
    cos / d^2 over the light's area is exactly that solid angle). The
    occluder hides the emitters with x < px + (EDGE_X - px) h / EDGE_H."""
    L = LIGHT
    x0 = np.full_like(px, L["x0"])
    if occluded:
        x0 = np.maximum(x0, px + (EDGE_X - px) * L["h"] / EDGE_H)
    omega = np.where(x0 < L["x1"], rect_solid_angle(px, pz, x0, L["x1"], L["z0"], L["z1"], L["h"]), 0.0)
    area = (L["x1"] - L["x0"]) * (L["z1"] - L["z0"])
    return ALBEDO * L["intensity"] / area * omega


def floor_render(tmp_path, samples, occluded):
    """(colour R, floor points x, z) of the floor pixels, the light made of
    `samples` emitters."""
    (tmp_path / "floor.obj").write_text("v -20 0 -20\nv 20 0 -20\nv 20 0 20\nv -20 0 20\nf 1 3 2\nf 1 4 3\n")
    (tmp_path / "occluder.obj").write_text(f"v -20 {EDGE_H} -20\nv {EDGE_X} {EDGE_H} -20\nv {EDGE_X} {EDGE_H} 20\n"
                                           f"v -20 {EDGE_H} 20\nf 1 3 2\nf 1 4 3\n")
    L = LIGHT
    objects = "  - {name: floor, mesh: floor.obj}\n" + (
        "  - {name: occluder, mesh: occluder.obj}\n" if occluded else "")
    path = tmp_path / "closed_form.yaml"
    path.write_text(f"""version: 1
frames: {{start: 0, end: 0, fps: 1}}
output: {{path: out/f_#.exr, resolution: [64, 48]}}
camera: {{eye: [0, 1.5, 2.5], look_at: [0, 0, 0], fov: 70}}
lights: [{{type: area, corner: [{L['x0']}, {L['h']}, {L['z0']}], edge_u: [{L['x1'] - L['x0']}, 0, 0],
          edge_v: [0, 0, {L['z1'] - L['z0']}], intensity: {L['intensity']}, samples: {samples}}}]
objects:
{objects}""")
    scene = AnimatedScene(path)
    cfg = config_of(scene, aovs=("P",), ambient=0.0)
    result = SceneRenderer(scene, cfg, shading_of(scene)).render(0.0)[1]
    y = result.aovs["P.Y"].reshape(-1)
    floor = np.isfinite(result.z.reshape(-1)) & (np.abs(y) < 1e-3)
    return (result.rgba[..., 0].reshape(-1)[floor], result.aovs["P.X"].reshape(-1)[floor],
            result.aovs["P.Z"].reshape(-1)[floor])


def test_a_square_lights_irradiance_on_a_plane_converges_to_the_closed_form(tmp_path):
    errors = []
    for samples in (4, 16, 64, 256):
        red, x, z = floor_render(tmp_path, samples, occluded=False)
        exact = exact_floor_colour(x, z, occluded=False)
        errors.append(float(np.max(np.abs(red / exact - 1))))
    assert errors[-1] < 5e-3, errors
    assert all(b < a for a, b in zip(errors, errors[1:])), errors


def test_the_penumbra_of_a_straight_edge_converges_to_the_closed_form(tmp_path):
    """Floor points see the light partly past the occluder's edge (x from
    -1 to 1 here); the error of the emitter sum falls faster than 1 /
    sqrt(samples) (independent random emitters), as the emitters'
    x coordinates are a van der Corput sequence: a 1D edge's error ~ 1 / N."""
    rows = []
    for samples in (16, 64, 256, 1024):
        red, x, z = floor_render(tmp_path, samples, occluded=True)
        exact = exact_floor_colour(x, z, occluded=True)
        full = exact_floor_colour(x, z, occluded=False)
        penumbra = (exact > 0.05 * full) & (exact < 0.95 * full)
        assert penumbra.sum() > 100
        rows.append((samples, float(np.sqrt(np.mean(((red - exact) / full)[penumbra] ** 2)))))
    n, err = np.array(rows).T
    slope = np.polyfit(np.log(n), np.log(err), 1)[0]
    assert err[-1] < 5e-3 and slope < -0.75, rows
