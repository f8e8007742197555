// The server's camera model (intuitf.render.camera: Camera.basis and Camera.frame) in the
// page, so that the page's rays are the server's rays for the same camera and picture size.
//
// World coordinates are voxel index × spacing, the spacing divided by its smallest component
// (one voxel is the unit length of opacity). The camera looks at the box's centre (plus pan);
// zoom 1 fits the box's bounding sphere across the picture's shorter side.

const RAD = Math.PI / 180;

function cross(a, b) {
  return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
}

function norm(a) {
  const n = Math.hypot(a[0], a[1], a[2]);
  return [a[0] / n, a[1] / n, a[2] / n];
}

/** Unit vectors {fwd, right, up} of a camera {azimuth, elevation, roll}. */
export function basis(cam) {
  const a = (cam.azimuth || 0) * RAD;
  const e = (cam.elevation || 0) * RAD;
  const r = (cam.roll || 0) * RAD;
  const toEye = [Math.sin(a) * Math.cos(e), -Math.cos(a) * Math.cos(e), Math.sin(e)];
  const up = [-Math.sin(a) * Math.sin(e), Math.cos(a) * Math.sin(e), Math.cos(e)];
  const fwd = [-toEye[0], -toEye[1], -toEye[2]];
  const right = cross(fwd, up);
  const upR = [0, 1, 2].map((i) => Math.cos(r) * up[i] - Math.sin(r) * right[i]);
  const rightR = cross(fwd, upR);
  return { fwd, right: norm(rightR), up: norm(upR) };
}

/**
 * The camera resolved for a box of physical size `extent` [x, y, z] and a picture of
 * width × height: what the ray caster needs (render/camera.py ViewFrame).
 */
export function frame(cam, extent, width, height) {
  const center = extent.map((v) => v / 2);
  const radius = Math.max(0.5 * Math.hypot(extent[0], extent[1], extent[2]), 1e-6);
  const { fwd, right, up } = basis(cam);
  const aspect = width / height;
  const fov = cam.fov || 30;
  const zoom = cam.zoom || 1;
  const ortho = cam.projection === "orthographic" || cam.orthographic === true;
  const half = Math.tan((fov * RAD) / 2);
  let short;
  let distance;
  if (ortho) {
    short = radius / zoom;
    distance = 2 * radius + 1;
  } else {
    distance = radius / Math.sin((fov * RAD) / 2);
    short = half / zoom;
  }
  const [hh, hw] = aspect >= 1 ? [short, short * aspect] : [short / aspect, short];
  const eye = [0, 1, 2].map((i) => center[i] - fwd[i] * distance);
  const pan = Array.isArray(cam.pan) ? cam.pan : [0, 0];
  return { eye, center, fwd, right, up, halfWidth: hw, halfHeight: hh, perspective: !ortho, pan, distance, width, height };
}

/** The world extent of a volume box: (dims - 1) × spacing / min(spacing). */
export function extentOf(dims, spacing) {
  const m = Math.min(spacing[0], spacing[1], spacing[2]);
  return [0, 1, 2].map((i) => ((dims[i] - 1) * spacing[i]) / m);
}
