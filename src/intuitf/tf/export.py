"""Transfer functions in the file formats of other tools: ParaView, 3D Slicer, VTK and ImageVis3D.

Every function here returns the file's text; :mod:`intuitf.tf.export_io` writes it.

**Units.** Exports speak the volume's original units: normalised value ``s`` becomes
``lo + s * (hi - lo)`` with ``(lo, hi)`` the TF's ``value_range`` or an explicit one.

**Faithfulness.** Gaussians are not piecewise linear, so the TF is sampled densely (4097 evenly
spaced values plus knots around every Gaussian, which keeps the narrowest Gaussians' peaks), and
then only the points that linear interpolation cannot reproduce within a tolerance are kept
(Ramer–Douglas–Peucker on the vertical error). Files stay small; a tool that interpolates
linearly between the points (all of them do) reproduces :meth:`GaussianTF.opacity` and
:meth:`GaussianTF.color` to about ``OPACITY_TOLERANCE`` and ``COLOR_TOLERANCE``.

**Opacity convention.** A Gaussian's height is an opacity per unit length of *one voxel*.
VTK and ParaView say the same with ``ScalarOpacityUnitDistance`` set to the voxel size in world
units; the VTK snippet sets it and the ParaView preset records it (ParaView keeps it on the
representation, not in presets: set *Scalar Opacity Unit Distance* to that value by hand).
3D Slicer's ``.vp`` files cannot store it and Slicer leaves VTK's default of 1 world unit (mm),
so the Slicer export converts the opacities to that unit: ``1 - (1 - a) ** (1 / voxel)``.
ImageVis3D's ``.1dt`` is written per voxel.

Formats:

- ``paraview``: a colour-map preset for ParaView's *Import Presets* (JSON): a list with one
  object holding ``Name``, ``ColorSpace`` = ``"RGB"``, ``RGBPoints`` = ``[x, r, g, b, ...]`` and
  ``Points`` = ``[x, opacity, 0.5, 0.0, ...]`` (midpoint 0.5 and sharpness 0 mean linear).
- ``slicer``: the text written by Slicer's ``vtkMRMLVolumePropertyStorageNode`` (checked
  against Slicer's source): one value per line, in this order: interpolation type (1 = linear),
  shade (0/1), diffuse, ambient, specular, specular power, then the scalar opacity as
  ``"<2N> x1 a1 ... xN aN"``, the gradient opacity in the same form, and the colour as
  ``"<4N> x1 r1 g1 b1 ..."``. Slicer requires strictly increasing x.
- ``vtk``: a Python snippet that builds ``color_tf`` (vtkColorTransferFunction), ``opacity_tf``
  (vtkPiecewiseFunction) and ``volume_property`` (vtkVolumeProperty).
- ``1dt``: ImageVis3D's 1D transfer function: the number of entries on the first line, then one
  ``r g b a`` line per entry, the entries spread evenly over the value range.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from intuitf.errors import TransferFunctionError
from intuitf.tf.gaussian import GaussianTF

#: Export format name -> file suffix.
EXPORT_FORMATS: dict[str, str] = {
    "paraview": ".paraview.json",
    "slicer": ".vp",
    "vtk": ".vtk.py",
    "1dt": ".1dt",
}

#: Largest opacity error linear interpolation between exported points may make (at the samples).
OPACITY_TOLERANCE = 0.002
#: Largest colour-channel error linear interpolation between exported points may make.
COLOR_TOLERANCE = 0.004
#: Evenly spaced samples over [0, 1] before simplification.
DENSE_SAMPLES = 4097

#: Lighting written with the opacity and colour (Slicer and VTK exports).
SHADING = {"ambient": 0.1, "diffuse": 0.9, "specular": 0.2, "specular_power": 10.0}


@dataclass(frozen=True)
class ControlPoints:
    """A TF as the piecewise-linear points other tools store, in original units.

    ``opacity`` has rows ``(x, a)``, ``color`` rows ``(x, r, g, b)``; x strictly increasing.
    ``a`` is an opacity per ``unit_distance`` world units.
    """

    opacity: np.ndarray
    color: np.ndarray
    value_range: tuple[float, float]
    unit_distance: float


def resolve_value_range(
    tf: GaussianTF, value_range: tuple[float, float] | None = None
) -> tuple[float, float]:
    """The original-units range to export with: ``value_range`` if given, else the TF's own."""
    vr = value_range if value_range is not None else tf.value_range
    if vr is None:
        raise TransferFunctionError(
            "This transfer function does not know the volume's value range, so it cannot be "
            "written in the volume's own units.",
            "Pass the range of the data, e.g. --value-range -1024,3071 (or value_range=(lo, hi)).",
        )
    try:
        lo, hi = (float(v) for v in vr)
    except (TypeError, ValueError) as exc:
        raise TransferFunctionError(
            f"A value range is two numbers (low, high), got {vr!r}."
        ) from exc
    if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
        raise TransferFunctionError(
            f"A value range needs finite numbers with high > low, got ({lo:g}, {hi:g})."
        )
    return lo, hi


def _check_unit_distance(unit_distance: float) -> float:
    u = float(unit_distance)
    if not (math.isfinite(u) and u > 0):
        raise TransferFunctionError(
            f"The voxel size (opacity unit distance) must be a positive number, got {unit_distance!r}."
        )
    return u


def dense_samples(tf: GaussianTF) -> np.ndarray:
    """Normalised values at which to sample ``tf``: an even grid plus knots around each Gaussian."""
    knots = [np.linspace(0.0, 1.0, DENSE_SAMPLES)]
    offsets = np.array([-3.0, -2.0, -1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0, 3.0])
    for g in tf.gaussians:
        knots.append(g.mean + offsets * g.width)
    s = np.unique(np.clip(np.concatenate(knots), 0.0, 1.0))
    # Knots almost on top of a grid value add nothing and would crowd the files' x values.
    keep = np.concatenate([[True], np.diff(s) > 1e-7])
    keep[-1] = True
    return s[keep] if keep.sum() >= 2 else np.array([0.0, 1.0])


def simplify_polyline(x: np.ndarray, y: np.ndarray, tolerance: float) -> np.ndarray:
    """Indices of the points of ``(x, y)`` to keep so that linear interpolation through them is
    within ``tolerance`` of every ``y`` (all columns of a 2D ``y``); first and last always kept.

    Ramer–Douglas–Peucker with the vertical (not perpendicular) distance, since x and y have
    unrelated units.
    """
    x = np.asarray(x, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64).reshape(len(x), -1)
    n = len(x)
    keep = np.zeros(n, dtype=bool)
    keep[0] = keep[-1] = True
    stack = [(0, n - 1)]
    while stack:
        i, j = stack.pop()
        if j - i < 2:
            continue
        t = (x[i + 1 : j] - x[i]) / (x[j] - x[i])
        line = yy[i] + t[:, None] * (yy[j] - yy[i])
        err = np.abs(yy[i + 1 : j] - line).max(axis=1)
        k = int(np.argmax(err))
        if err[k] > tolerance:
            m = i + 1 + k
            keep[m] = True
            stack.append((i, m))
            stack.append((m, j))
    return np.flatnonzero(keep)


def control_points(
    tf: GaussianTF,
    value_range: tuple[float, float] | None = None,
    *,
    unit_distance: float = 1.0,
    opacity_unit: float | None = None,
) -> ControlPoints:
    """Sample ``tf`` densely and keep the points a piecewise-linear tool needs.

    ``unit_distance`` is the world length of one voxel. Opacities are written per
    ``opacity_unit`` world units (default: per voxel, i.e. unchanged).
    """
    lo, hi = resolve_value_range(tf, value_range)
    u = _check_unit_distance(unit_distance)
    s = dense_samples(tf)
    x = lo + s * (hi - lo)
    a = tf.opacity(s)
    if opacity_unit is not None and opacity_unit != u:
        # Same absorption over a different unit length: 1 - (1 - a) ** (new / old).
        a = 1.0 - np.power(1.0 - a, _check_unit_distance(opacity_unit) / u)
    rgb = tf.color(s)
    ia = simplify_polyline(s, a, OPACITY_TOLERANCE)
    ic = simplify_polyline(s, rgb, COLOR_TOLERANCE)
    return ControlPoints(
        opacity=np.column_stack([x[ia], a[ia]]),
        color=np.column_stack([x[ic], rgb[ic]]),
        value_range=(lo, hi),
        unit_distance=u,
    )


def _x(v: float) -> str:
    # Shortest text that reads back as the same double: x values stay strictly increasing.
    return repr(float(v))


def _v(v: float) -> str:
    return f"{float(v):.6g}"


def _tf_name(tf: GaussianTF) -> str:
    return tf.name or "intuitf"


# -- ParaView -------------------------------------------------------------------------------
def to_paraview_json(
    tf: GaussianTF, value_range: tuple[float, float] | None = None, *, unit_distance: float = 1.0
) -> str:
    """A ParaView colour-map preset (for *Import Presets*) with colours and opacities."""
    cp = control_points(tf, value_range, unit_distance=unit_distance)
    rgb_points = [float(v) for row in cp.color for v in row]
    points = [float(v) for x, a in cp.opacity for v in (x, a, 0.5, 0.0)]
    preset = {
        "Name": _tf_name(tf),
        "Creator": "intuitf",
        "ColorSpace": "RGB",
        "RGBPoints": rgb_points,
        "Points": points,
        "NanColor": [0.0, 0.0, 0.0],
        # Not read by ParaView (it lives on the representation): set it there by hand.
        "ScalarOpacityUnitDistance": cp.unit_distance,
        "Notes": (
            "Opacity is per voxel. In ParaView set the volume representation's "
            f"'Scalar Opacity Unit Distance' to {cp.unit_distance:g} (the voxel size); values "
            f"are in the data's own units, range {cp.value_range[0]:g} to {cp.value_range[1]:g}."
        ),
    }
    return json.dumps([preset], indent=1) + "\n"


# -- 3D Slicer ------------------------------------------------------------------------------
def to_slicer_vp(
    tf: GaussianTF,
    value_range: tuple[float, float] | None = None,
    *,
    unit_distance: float = 1.0,
    shade: bool = True,
) -> str:
    """A 3D Slicer volume property (``.vp``); opacities converted to per 1 world unit (mm)."""
    cp = control_points(tf, value_range, unit_distance=unit_distance, opacity_unit=1.0)
    lo, hi = cp.value_range
    opacity = " ".join(f"{_x(x)} {_v(a)}" for x, a in cp.opacity)
    color = " ".join(f"{_x(x)} {_v(r)} {_v(g)} {_v(b)}" for x, r, g, b in cp.color)
    lines = [
        "1",  # interpolation: linear
        "1" if shade else "0",
        _v(SHADING["diffuse"]),
        _v(SHADING["ambient"]),
        _v(SHADING["specular"]),
        _v(SHADING["specular_power"]),
        f"{2 * len(cp.opacity)} {opacity}",
        # Gradient opacity 1 everywhere: the TF does not depend on the gradient.
        f"4 0 1 {_x(max(hi - lo, 1.0))} 1",
        f"{4 * len(cp.color)} {color}",
    ]
    return "\n".join(lines) + "\n"


# -- VTK ------------------------------------------------------------------------------------
def to_vtk_python(
    tf: GaussianTF, value_range: tuple[float, float] | None = None, *, unit_distance: float = 1.0
) -> str:
    """A Python snippet building ``color_tf``, ``opacity_tf`` and ``volume_property`` with VTK."""
    cp = control_points(tf, value_range, unit_distance=unit_distance)
    lo, hi = cp.value_range
    name = json.dumps(_tf_name(tf))  # a safe one-line rendering of any name
    color_rows = "\n".join(f"    ({_x(x)}, {_v(r)}, {_v(g)}, {_v(b)})," for x, r, g, b in cp.color)
    opacity_rows = "\n".join(f"    ({_x(x)}, {_v(a)})," for x, a in cp.opacity)
    return f'''"""Transfer function {name} made with intuitf, for VTK.

Values are in the volume's own units ({lo:g} to {hi:g}). Opacity is per voxel, so
SCALAR_OPACITY_UNIT_DISTANCE is the voxel size in world units: change it if yours differs.

Use it from Python:

    import runpy
    tf = runpy.run_path("this_file.vtk.py")
    volume.SetProperty(tf["volume_property"])  # volume: your vtkVolume

or take tf["color_tf"] (vtkColorTransferFunction) and tf["opacity_tf"] (vtkPiecewiseFunction).
"""

from vtkmodules.vtkCommonDataModel import vtkPiecewiseFunction
from vtkmodules.vtkRenderingCore import vtkColorTransferFunction, vtkVolumeProperty

VALUE_RANGE = ({_x(lo)}, {_x(hi)})
SCALAR_OPACITY_UNIT_DISTANCE = {_x(cp.unit_distance)}

# (value, red, green, blue)
COLOR_POINTS = [
{color_rows}
]

# (value, opacity per voxel)
OPACITY_POINTS = [
{opacity_rows}
]

color_tf = vtkColorTransferFunction()
color_tf.SetColorSpaceToRGB()
for _x, _r, _g, _b in COLOR_POINTS:
    color_tf.AddRGBPoint(_x, _r, _g, _b)

opacity_tf = vtkPiecewiseFunction()
for _x, _a in OPACITY_POINTS:
    opacity_tf.AddPoint(_x, _a)

volume_property = vtkVolumeProperty()
volume_property.SetColor(color_tf)
volume_property.SetScalarOpacity(opacity_tf)
volume_property.SetScalarOpacityUnitDistance(SCALAR_OPACITY_UNIT_DISTANCE)
volume_property.SetInterpolationTypeToLinear()
volume_property.ShadeOn()
volume_property.SetAmbient({_v(SHADING["ambient"])})
volume_property.SetDiffuse({_v(SHADING["diffuse"])})
volume_property.SetSpecular({_v(SHADING["specular"])})
volume_property.SetSpecularPower({_v(SHADING["specular_power"])})
'''


# -- ImageVis3D -----------------------------------------------------------------------------
def to_1dt(
    tf: GaussianTF,
    value_range: tuple[float, float] | None = None,
    *,
    unit_distance: float = 1.0,
    entries: int = 4096,
) -> str:
    """An ImageVis3D 1D transfer function with ``entries`` evenly spaced entries (per voxel).

    The file has no units: its entries span the data range, so ``value_range`` is not needed.
    """
    _check_unit_distance(unit_distance)
    if not 2 <= int(entries) <= 65536:
        raise TransferFunctionError(f"A .1dt file has 2 to 65536 entries, got {entries}.")
    lut = tf.lut(int(entries)).astype(np.float64)
    rows = "\n".join(" ".join(_v(v) for v in row) for row in lut)
    return f"{int(entries)}\n{rows}\n"


_FORMATTERS: dict[str, Callable[..., str]] = {
    "paraview": to_paraview_json,
    "slicer": to_slicer_vp,
    "vtk": to_vtk_python,
    "1dt": to_1dt,
}


def export_tf(
    tf: GaussianTF,
    fmt: str,
    value_range: tuple[float, float] | None = None,
    *,
    unit_distance: float = 1.0,
) -> str:
    """The text of ``tf`` in format ``fmt`` (a key of :data:`EXPORT_FORMATS`).

    ``value_range`` (original units) overrides the TF's own; ``unit_distance`` is the world
    length of one voxel (the voxel spacing), the unit of the Gaussians' heights.
    """
    try:
        formatter = _FORMATTERS[fmt]
    except KeyError:
        raise TransferFunctionError(
            f"Unknown export format {fmt!r}.",
            f"Choose one of: {', '.join(EXPORT_FORMATS)}.",
        ) from None
    return formatter(tf, value_range, unit_distance=unit_distance)
