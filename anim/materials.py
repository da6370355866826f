"""Material dicts as anim/scene.py keeps them (diffuse, specular, shininess,
texture, texture_space): the default material, and metallic-roughness
materials (glTF's pbrMetallicRoughness, USD's UsdPreviewSurface) as
frustrace's Lambert + Blinn-Phong ones (raycore/shading/shade.py).

One mapping for both formats: the base colour is the diffuse colour; the
roughness r becomes the Blinn-Phong exponent of the same Beckmann width,
2 / r^4 - 2 (Walter et al. 2007), clamped to [1, 10^4]; the specular weight
is 0.04 (a dielectric's reflectance at normal incidence) rising to 1 with
the metallic factor.
"""

DEFAULT_MATERIAL = {"diffuse": (0.8, 0.8, 0.8), "specular": 0.0, "shininess": 32.0, "texture": None,
                    "texture_space": "auto"}


def pbr_material(name, colour, roughness, metallic, texture=None, texture_space="srgb", uv_set="st"):
    """A material dict with anim/scene.py's keys (plus name and uv_set)."""
    alpha2 = max(float(roughness), 1e-3) ** 4
    return {"name": name,
            "diffuse": tuple(float(min(max(c, 0.0), 1e6)) for c in list(colour)[:3]),
            "specular": 0.04 + 0.96 * min(max(float(metallic), 0.0), 1.0),
            "shininess": float(min(max(2.0 / alpha2 - 2.0, 1.0), 1e4)),
            "texture": texture, "texture_space": texture_space, "uv_set": uv_set}
