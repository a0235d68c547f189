"""Building blocks of the scene dictionaries (``mi.load_dict``): the box-filtered film, the
camera, diffuse BSDFs, rectangles, the open Cornell-style room, the ceiling light and the objects
in front of the mirror wall. Shared by the steady, sequence and transient catalogues and by scene
files."""
from __future__ import annotations

from ...resolution import parse_res


def film_dict(res) -> dict:
    res = parse_res(res)
    return {"type": "hdrfilm", "width": res.width, "height": res.height,
            "rfilter": {"type": "box"}, "pixel_format": "rgb", "component_format": "float32"}


def camera_dict(mi, res, origin, target, fov: float = 39.3, up=(0, 1, 0)) -> dict:
    """A perspective camera whose ``fov`` (degrees) spans x of a square image, and the
    smaller side of any other (dbench.resolution)."""
    return {"type": "perspective", "fov": fov, "fov_axis": parse_res(res).fov_axis,
            "to_world": mi.ScalarTransform4f().look_at(origin=origin, target=target, up=up),
            "film": film_dict(res), "sampler": {"type": "independent"}}


def diffuse_bsdf(rgb) -> dict:
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": list(rgb)}}


def rect_shape(mi, to_world, bsdf: dict, emitter: dict | None = None) -> dict:
    d = {"type": "rectangle", "to_world": to_world, "bsdf": bsdf}
    if emitter:
        d["emitter"] = emitter
    return d


def room_shapes(mi, back_bsdf=None, left_bsdf=None, right_bsdf=None, floor_bsdf=None) -> dict:
    """An open Cornell-style room spanning [-1, 1]³, open towards +z where the camera sits."""
    T = mi.ScalarTransform4f
    white = diffuse_bsdf((0.75, 0.75, 0.75))
    return {
        "floor": rect_shape(mi, T().translate([0, -1, 0]).rotate([1, 0, 0], -90), floor_bsdf or white),
        "ceiling": rect_shape(mi, T().translate([0, 1, 0]).rotate([1, 0, 0], 90), white),
        "back": rect_shape(mi, T().translate([0, 0, -1]), back_bsdf or white),
        "left": rect_shape(mi, T().translate([-1, 0, 0]).rotate([0, 1, 0], 90),
                      left_bsdf or diffuse_bsdf((0.63, 0.065, 0.05))),
        "right": rect_shape(mi, T().translate([1, 0, 0]).rotate([0, 1, 0], -90),
                       right_bsdf or diffuse_bsdf((0.14, 0.45, 0.091))),
    }


def ceiling_light(mi, size: float = 0.25, radiance=(17.0, 12.0, 4.0)) -> dict:
    T = mi.ScalarTransform4f
    return rect_shape(mi, T().translate([0, 0.99, 0]).rotate([1, 0, 0], 90).scale(size),
                 diffuse_bsdf((0, 0, 0)), {"type": "area", "radiance": {"type": "rgb",
                                                                   "value": list(radiance)}})


def mirror_objects(mi) -> dict:
    """The objects in front of the mirror wall (``mirrors``, and ``mirror-pan`` in
    dbench/datasets/sequence/load.py): a blue plastic ball, a chrome ball and a rotated box."""
    T = mi.ScalarTransform4f
    return {
        "ball": {"type": "sphere", "center": [-0.45, -0.6, 0.2], "radius": 0.4,
                 "bsdf": {"type": "plastic", "diffuse_reflectance":
                          {"type": "rgb", "value": [0.1, 0.25, 0.7]}, "int_ior": 1.5}},
        "chrome": {"type": "sphere", "center": [0.5, -0.7, 0.45], "radius": 0.3,
                   "bsdf": {"type": "conductor", "material": "Cr"}},
        "block": {"type": "cube",
                  "to_world": T().translate([0.35, -0.75, -0.45]).rotate([0, 1, 0], 25)
                  .scale(0.25),
                  "bsdf": diffuse_bsdf((0.8, 0.6, 0.2))},
    }
