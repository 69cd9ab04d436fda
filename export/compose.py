"""Results that compose in place over the artist's set they were simulated on.

When a scene's obstacles come from a USD stage (:func:`warpsim.obstacles_from_usd`),
:func:`warpsim.export.write_usd` writes a root stage that opens over that set::

    RESULT.usdc                 upAxis and metersPerUnit: the set's
      subLayers = [./set.usda]  the set itself, relative to the result: its prims keep their
                                paths, materials, lights and cameras; no copy of the boxes
      /World                    warpsim's prim (default prim): warpsim:dt, warpsim:scene
        /Looks                  the spheres' materials
        /Spheres                the PointInstancer, as write_usd writes it: positions [m] and
                                radii [m], under xformOpOrder = [!resetXformStack!,
                                xformOp:scale] with scale = 1 / metersPerUnit on each axis
                                (then the writer's own per-frame origin, if it has one)

The instancer's own transform maps its metres onto the set's units, and ``!resetXformStack!``
keeps it in the stage's world frame even when the set has a ``/World`` prim of its own with a
transform. The simulation ran in the set's axes, so nothing is rotated. ``read_usd`` reads the
instancer's stored values: the trajectory in metres, exactly as written.
"""

from __future__ import annotations

import os
from pathlib import Path

from pxr import Gf, Sdf, UsdGeom, Vt

RESET_XFORM_STACK = "!resetXformStack!"


def check_output(stage_set, path) -> None:
    """Refuse an output that would replace the set it composes over.

    Raises:
        ValueError: ``path`` is the set's file.
    """
    if Path(path).resolve() == Path(stage_set.path).resolve():
        raise ValueError(f"output {str(path)!r} is the set the result composes over; write "
                         f"the result to another file")


def set_asset_path(set_path, output) -> str:
    """The set's path as the result's sublayer names it: relative to the result's folder
    (``./set.usda``, ``../sets/set.usda``), absolute when no relative path exists."""
    folder = Path(output).resolve().parent
    try:
        relative = Path(os.path.relpath(Path(set_path).resolve(), folder)).as_posix()
    except ValueError:  # another drive
        return Path(set_path).resolve().as_posix()
    return relative if relative.startswith("../") else f"./{relative}"


def over_set(layer: Sdf.Layer, stage_set, output, instancer: str) -> Sdf.Layer:
    """A copy of warpsim's root ``layer`` that composes over ``stage_set``'s stage.

    The copy is a layer without a stage (no composition, so the relative sublayer path is never
    resolved against the working directory); the caller writes it atomically.

    Args:
        layer: what :func:`warpsim.export.write_usd` built (spheres, materials; no obstacles).
        stage_set: the :class:`warpsim.export.stage_in.StageSet` the obstacles came from.
        output: the file the result is written to (the sublayer path is relative to it).
        instancer: the path of the sphere instancer in ``layer`` (``/World/Spheres``).

    Returns:
        The composed root layer, anonymous.

    Raises:
        ValueError: ``output`` is the set itself.
    """
    check_output(stage_set, output)
    out = Sdf.Layer.CreateAnonymous(f"composed{Path(output).suffix.lower()}")
    out.TransferContent(layer)
    asset = set_asset_path(stage_set.path, output)
    out.subLayerPaths.append(asset)
    out.pseudoRoot.SetInfo(UsdGeom.Tokens.upAxis, stage_set.up_axis)
    out.pseudoRoot.SetInfo(UsdGeom.Tokens.metersPerUnit, float(stage_set.meters_per_unit))
    in_set_units(out.GetPrimAtPath(instancer), stage_set)
    out.documentation = (f"{layer.documentation} Composed over {asset} "
                         f"({stage_set.up_axis} up, {stage_set.meters_per_unit:g} m per unit): "
                         f"sphere positions and radii in metres, scaled to the set's units.")
    return out


def in_set_units(spheres: Sdf.PrimSpec, stage_set) -> None:
    """Give the spheres' prim (an instancer, or the ``Xform`` over a sharded run's instancers)
    the transform that maps its metres onto the set's units in the stage's world frame:
    ``[!resetXformStack!, xformOp:scale, ...its own ops]``."""
    scale = 1.0 / float(stage_set.meters_per_unit)
    op = Sdf.AttributeSpec(spheres, "xformOp:scale", Sdf.ValueTypeNames.Double3)
    op.default = Gf.Vec3d(scale, scale, scale)
    order = spheres.attributes.get("xformOpOrder")  # the writer's own ops (an origin) go last
    inner = list(order.default) if order is not None and order.default else []
    if order is None:
        order = Sdf.AttributeSpec(spheres, "xformOpOrder", Sdf.ValueTypeNames.TokenArray,
                                  Sdf.VariabilityUniform)
    order.default = Vt.TokenArray([RESET_XFORM_STACK, "xformOp:scale", *inner])
