"""glTF scenes baked directly (`cook scene.gltf`), checked against ground truth: closed forms
(an emissive quad with KHR_materials_emissive_strength over a plane, a KHR_lights_punctual point
light over a plane) and, for light bouncing between surfaces, an independent renderer: a
Cornell-box-like scene rendered by Mitsuba 3 with an irradiance meter on every face.

What is compared is what the runtime shows: the lightmap pages as written (OpenEXR), sampled
bilinearly at points spread over each surface through its instance's lightmap region.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gltf_scenes import Scene
from lightmap_samples import baked, polygon_irradiance, surface_samples

# ---- closed forms through a glTF scene --------------------------------------------------------------


def test_emissive_quad_with_emissive_strength_over_a_plane_matches_the_closed_form(tmp_path):
    s = Scene()
    floor = s.quad_mesh("floor", (4, 4), s.material("floor", color=(0.8, 0.8, 0.8, 1)))
    s.node("floor", mesh=floor)
    # A black emitter (it reflects nothing back), emissive factor x strength = 300 nits.
    lamp = s.quad_mesh("lamp", (1, 1), s.material("lamp", color=(0, 0, 0, 1), emissive=(1.0, 0.5, 0.25), emissive_strength=300.0), facing_down=True)
    s.node("lamp", mesh=lamp, translation=[0, 1, 0])
    scene, pages = baked(s.write(tmp_path / "lamp.gltf"), samples=256)
    p, b = surface_samples(scene, pages, "floor")
    central = (np.abs(p[:, 0]) < 1.5) & (np.abs(p[:, 2]) < 1.5)
    quad = np.array([[-0.5, 1, -0.5], [0.5, 1, -0.5], [0.5, 1, 0.5], [-0.5, 1, 0.5]])
    want = polygon_irradiance(p[central], np.array([0.0, 1.0, 0.0]), quad)[:, None] / math.pi * 300.0 * np.array([1.0, 0.5, 0.25])
    ratio = b[central].sum(0) / want.sum(0)
    print(f"emissive quad (strength 300) over a plane: baked / analytic B per channel {np.round(ratio, 4)}")
    np.testing.assert_allclose(ratio, 1.0, atol=0.01, err_msg=f"baked / analytic B: {ratio}")


def test_khr_point_light_over_a_plane_matches_the_closed_form(tmp_path):
    s = Scene()
    s.node("floor", mesh=s.quad_mesh("floor", (4, 4), s.material("floor", color=(0.8, 0.8, 0.8, 1))))
    # 120 cd, warm; the light's node places it 1.5 m up.
    s.light("bulb", "point", intensity=120.0, color=(1.0, 0.8, 0.6), node={"translation": [0.3, 1.5, -0.2]})
    scene, pages = baked(s.write(tmp_path / "bulb.gltf"), samples=64)
    assert [(l.kind, l.position) for l in scene.lights] == [("point", (0.3, 1.5, -0.2))]
    p, b = surface_samples(scene, pages, "floor")
    central = (np.abs(p[:, 0]) < 1.5) & (np.abs(p[:, 2]) < 1.5)
    d = np.array([0.3, 1.5, -0.2]) - p[central]
    r = np.linalg.norm(d, axis=1)
    e = 120.0 * (d[:, 1] / r) / r ** 2
    want = e[:, None] / math.pi * np.array([1.0, 0.8, 0.6])
    ratio = b[central].sum(0) / want.sum(0)
    print(f"KHR point light over a plane: baked / analytic B per channel {np.round(ratio, 4)}")
    np.testing.assert_allclose(ratio, 1.0, atol=0.01, err_msg=f"baked / analytic B: {ratio}")
    # A point light's next-event estimate has no noise: every point within 2% (bilinear filtering
    # of a curved field between texel centres is the rest).
    per_point = b[central, 0] / want[:, 0]
    assert np.abs(per_point - 1).max() < 0.02, np.abs(per_point - 1).max()


# ---- multi-bounce against an independent renderer ---------------------------------------------------

WHITE, RED, GREEN = (0.75, 0.75, 0.75), (0.63, 0.065, 0.05), (0.14, 0.45, 0.09)
LIGHT_RADIANCE = (40.0, 36.0, 30.0)  # nits
BOUNCES = 6  # the same truncation in both renderers: Mitsuba's max_depth is BOUNCES + 1


def cornell_faces():
    """(name, colour, centre, normal (the way it faces), u axis, v axis, half extents) of every
    face: a 2 m box open at +Z, and a 0.6 m cube floating inside."""
    faces = [
        ("floor", WHITE, (0, 0, 0), (0, 1, 0), (1, 0, 0), (0, 0, 1), (1, 1)),
        ("ceiling", WHITE, (0, 2, 0), (0, -1, 0), (1, 0, 0), (0, 0, 1), (1, 1)),
        ("back", WHITE, (0, 1, -1), (0, 0, 1), (1, 0, 0), (0, 1, 0), (1, 1)),
        ("left", RED, (-1, 1, 0), (1, 0, 0), (0, 0, 1), (0, 1, 0), (1, 1)),
        ("right", GREEN, (1, 1, 0), (-1, 0, 0), (0, 0, 1), (0, 1, 0), (1, 1)),
    ]
    c, h = np.array([0.3, 0.7, -0.2]), 0.3
    for axis, name in enumerate(("x", "y", "z")):
        for sign in (-1, 1):
            n = np.zeros(3)
            n[axis] = sign
            u = np.zeros(3)
            u[(axis + 1) % 3] = 1
            faces.append((f"cube{'-+'[sign > 0]}{name}", WHITE, tuple(c + n * h), tuple(n), tuple(u), tuple(np.cross(n, u)), (h, h)))
    return faces


def face_node(s: Scene, name, colour, centre, normal, u, v, half) -> None:
    """A rectangle facing `normal`, as one mesh on one node (so each face has its own lightmap)."""
    centre, normal, u, v = (np.asarray(x, np.float64) for x in (centre, normal, u, v))
    corners = np.array([centre + a * half[0] * u + b * half[1] * v for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    idx = [0, 1, 2, 0, 2, 3] if np.dot(np.cross(u, v), normal) > 0 else [0, 2, 1, 0, 3, 2]
    uv = [[0, 0], [1, 0], [1, 1], [0, 1]]
    m = s.mesh_arrays(name, corners, np.tile(normal, (4, 1)), uv, idx, s.material(name, color=(*colour, 1)))
    s.node(name, mesh=m)


LIGHT = (np.array([0.0, 1.999, 0.0]), 0.35)  # centre, half size; facing down


def cornell_gltf(path: Path) -> Path:
    s = Scene()
    for f in cornell_faces():
        face_node(s, *f)
    peak = max(LIGHT_RADIANCE)
    lamp = s.quad_mesh("lamp", (2 * LIGHT[1], 2 * LIGHT[1]),
                       s.material("lamp", color=(0, 0, 0, 1), emissive=[c / peak for c in LIGHT_RADIANCE], emissive_strength=peak), facing_down=True)
    s.node("lamp", mesh=lamp, translation=LIGHT[0].tolist())
    return s.write(path)


def mitsuba_face_irradiance(samples: int, pixels: int = 64) -> dict[str, np.ndarray]:
    """Mitsuba 3's mean irradiance E (RGB) over every face of the box, from its path tracer.

    Each face is seen by an orthographic camera a tenth of a millimetre in front of it, its
    image covering exactly the face, so every pixel is an equal piece of it and nothing stands
    between (the floating cube never touches a wall). The mean radiance the face sends out is
    its albedo times E / pi (Lambertian, not emissive). Mitsuba's irradiancemeter would measure
    E directly but samples cosine directions at the face without next-event estimation: 60x
    slower for the same noise here. max_depth BOUNCES + 2: the camera ray, then the face's
    direct light (our bounces = 0), then one more per bounce."""
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    T = mi.ScalarTransform4f

    def frame(centre, z, x, y, sx, sy):
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = np.asarray(x) * sx, np.asarray(y) * sy, z, centre
        return T(m.tolist())

    def rectangle(centre, normal, u, v, half):
        # Mitsuba's rectangle spans [-1, 1]^2 in xy and faces +z.
        v = np.asarray(v) if np.dot(np.cross(u, v), normal) > 0 else -np.asarray(v)
        return frame(centre, normal, u, v, *half)

    shapes = {}
    for name, colour, centre, normal, u, v, half in cornell_faces():
        shapes[name] = {"type": "rectangle", "to_world": rectangle(centre, normal, u, v, half),
                        "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(colour)}}}
    centre, half = LIGHT
    shapes["lamp"] = {"type": "rectangle", "to_world": rectangle(centre, (0, -1, 0), (1, 0, 0), (0, 0, 1), (half, half)),
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0, 0, 0]}},
                      "emitter": {"type": "area", "radiance": {"type": "rgb", "value": list(LIGHT_RADIANCE)}}}
    out = {}
    for name, colour, centre, normal, u, v, half in cornell_faces():
        normal, u = np.asarray(normal, np.float64), np.asarray(u, np.float64)
        look = -normal  # the camera looks along its +z
        camera = {"type": "orthographic", "to_world": frame(np.asarray(centre) + 1e-4 * normal, look, u, np.cross(look, u), *half),
                  "near_clip": 1e-6, "far_clip": 10.0,
                  "film": {"type": "hdrfilm", "width": pixels, "height": pixels, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                  "sampler": {"type": "independent", "sample_count": samples}}
        scene = mi.load_dict({"type": "scene", "integrator": {"type": "path", "max_depth": BOUNCES + 2}, **shapes, "camera": camera})
        radiance = np.array(mi.render(scene, sensor=0, spp=samples), np.float64).reshape(-1, 3).mean(0)
        out[name] = radiance / np.asarray(colour) * math.pi
    return out


def test_cornell_box_matches_mitsuba_face_by_face(tmp_path):
    reference = mitsuba_face_irradiance(samples=128)
    scene, pages = baked(cornell_gltf(tmp_path / "cornell.gltf"), samples=512, bounces=BOUNCES)
    errors = {}
    for name, *_ in cornell_faces():
        _, b = surface_samples(scene, pages, name, count=8192)
        ours = b.mean(0) * math.pi  # B = E / pi
        want = reference[name]
        # Luminance-weighted: a channel near zero (the red wall's green) carries little light.
        weight = np.array([0.2126, 0.7152, 0.0722])
        errors[name] = float(abs(ours @ weight / (want @ weight) - 1))
    median = float(np.median(list(errors.values())))
    print(f"Cornell box against Mitsuba, per face |ours/theirs - 1| of luminance: median {median:.2%}, "
          f"largest {max(errors.values()):.2%}; " + ", ".join(f"{k} {v:.2%}" for k, v in errors.items()))
    assert median <= 0.01 and max(errors.values()) <= 0.03, {k: f"{v:.2%}" for k, v in errors.items()}
