"""VTK reference renderings with the same volume, TF and camera as intuitf's renderer.

Used by the correctness tests (GPU mapper, the pixel reference for unshaded images) and by
``benchmarks/render.py`` (fixed-point mapper, the CPU speed baseline). Needs VTK with an
offscreen OpenGL context (EGL on Mesa llvmpipe works without a display).
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
os.environ.setdefault("MESA_SHADER_CACHE_DIR", os.path.join(tempfile.gettempdir(), "intuitf-mesa"))


def vtk_available() -> str | None:
    """None when VTK can render offscreen here, else the reason it cannot."""
    try:
        import vtk
    except ImportError as exc:  # pragma: no cover - depends on the machine
        return f"VTK is not installed ({exc})"
    try:
        win = vtk.vtkRenderWindow()
        win.SetOffScreenRendering(1)
        win.SetSize(8, 8)
        ren = vtk.vtkRenderer()
        win.AddRenderer(ren)
        win.Render()
        ok = win.SupportsOpenGL()
        win.Finalize()
    except Exception as exc:  # pragma: no cover - depends on the machine
        return f"VTK cannot open an offscreen OpenGL context ({exc})"
    return None if ok else "VTK cannot open an offscreen OpenGL context (no OpenGL support)"


class VTKScene:
    """One VTK volume scene sized and lit like an intuitf ``VolumeRenderer``.

    ``mapper`` is "gpu" (vtkOpenGLGPUVolumeRayCastMapper, jittering off) or "fixed"
    (vtkFixedPointVolumeRayCastMapper). Sample distance is locked to the renderer's.
    """

    def __init__(self, renderer, mapper: str = "gpu") -> None:
        import vtk
        from vtk.util import numpy_support

        self.vtk = vtk
        self.r = renderer
        vol = renderer.volume
        self.unit = float(min(vol.spacing))
        img = vtk.vtkImageData()
        img.SetDimensions(*vol.dims)
        img.SetSpacing(*vol.spacing)
        img.SetOrigin(0.0, 0.0, 0.0)
        flat = np.ascontiguousarray(vol.data).ravel()  # x fastest: VTK's point order
        arr = numpy_support.numpy_to_vtk(flat, deep=True, array_type=vtk.VTK_FLOAT)
        img.GetPointData().SetScalars(arr)
        self._img = img
        if mapper == "gpu":
            m = vtk.vtkOpenGLGPUVolumeRayCastMapper()
            m.SetUseJittering(0)
        elif mapper == "fixed":
            m = vtk.vtkFixedPointVolumeRayCastMapper()
            m.SetImageSampleDistance(1.0)
            m.SetAutoAdjustSampleDistances(0)
        else:
            raise ValueError(mapper)
        m.SetInputData(img)
        m.SetAutoAdjustSampleDistances(0)
        m.SetLockSampleDistanceToInputSpacing(0)
        m.SetSampleDistance(renderer.sample_distance * self.unit)
        m.SetBlendModeToComposite()
        self.mapper = m
        prop = vtk.vtkVolumeProperty()
        prop.SetInterpolationTypeToLinear()
        prop.SetScalarOpacityUnitDistance(self.unit)
        ka, kd, ks, shin = (float(v) for v in renderer.shade_params)
        if renderer.shading:
            prop.ShadeOn()
            prop.SetAmbient(ka)
            prop.SetDiffuse(kd)
            prop.SetSpecular(ks)
            prop.SetSpecularPower(shin)
        else:
            prop.ShadeOff()
        self.prop = prop
        self.color = vtk.vtkColorTransferFunction()
        self.opacity = vtk.vtkPiecewiseFunction()
        prop.SetColor(self.color)
        prop.SetScalarOpacity(self.opacity)
        actor = vtk.vtkVolume()
        actor.SetMapper(m)
        actor.SetProperty(prop)
        ren = vtk.vtkRenderer()
        ren.AddVolume(actor)
        ren.SetBackground(*renderer.background)
        win = vtk.vtkRenderWindow()
        win.SetOffScreenRendering(1)
        win.SetMultiSamples(0)
        win.AddRenderer(ren)
        win.SetSize(renderer.width, renderer.height)
        self.ren = ren
        self.win = win

    def set_tf(self, tf) -> None:
        """The TF's LUT as VTK nodes: alpha per unit length (VTK corrects for its step)."""
        lut = tf.lut(self.r.lut_size, 1.0)
        xs = np.linspace(0.0, 1.0, lut.shape[0])
        self.color.RemoveAllPoints()
        self.opacity.RemoveAllPoints()
        self.color.BuildFunctionFromTable(
            0.0, 1.0, lut.shape[0], lut[:, :3].astype(np.float64).ravel()
        )
        for x, a in zip(xs, lut[:, 3], strict=True):
            self.opacity.AddPoint(float(x), float(a))

    def set_camera(self, camera) -> None:
        f = self.r.frame(camera)
        u = self.unit
        cam = self.ren.GetActiveCamera()
        cam.SetFocalPoint(*(f.center * u))
        cam.SetPosition(*(f.eye * u))
        cam.SetViewUp(*f.up)
        if f.perspective:
            cam.ParallelProjectionOff()
            cam.SetViewAngle(f.vtk_view_angle())
        else:
            cam.ParallelProjectionOn()
            cam.SetParallelScale(f.half_height * u)
        self.ren.ResetCameraClippingRange()

    def render(self, tf, camera) -> np.ndarray:
        """uint8 RGB (H, W, 3), rows top to bottom."""
        self.set_tf(tf)
        self.set_camera(camera)
        self.win.Render()
        w, h = self.r.width, self.r.height
        from vtk.util import numpy_support

        buf = self.vtk.vtkUnsignedCharArray()
        self.win.GetRGBACharPixelData(0, 0, w - 1, h - 1, 1, buf)
        a = numpy_support.vtk_to_numpy(buf).reshape(h, w, 4)[::-1, :, :3]
        return np.ascontiguousarray(a)

    def close(self) -> None:
        self.win.Finalize()
