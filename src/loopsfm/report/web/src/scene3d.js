// Interactive 3D view (three.js): the points of the first model in their colours, one frustum
// per registered frame of that model, the camera path as a line; orbit, zoom and pan with the
// mouse; a click on a frustum selects its frame.
import {
  BufferGeometry,
  Color,
  DoubleSide,
  Float32BufferAttribute,
  Line,
  LineBasicMaterial,
  LineSegments,
  Mesh,
  MeshBasicMaterial,
  PerspectiveCamera,
  Points,
  PointsMaterial,
  Raycaster,
  Scene,
  SRGBColorSpace,
  Vector2,
  Vector3,
  WebGLRenderer,
} from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

import { el, fmt, isNumber } from './dom.js';

const kFrustumColour = '#1f5fd6';
const kSelectedColour = '#ff7a00';
const kPathColour = '#d6452b';
const kBackground = '#ffffff';
// Camera models whose second parameter is fy (COLMAP's order); the others have one focal.
const kTwoFocalModels = new Set(['PINHOLE', 'OPENCV', 'OPENCV_FISHEYE', 'FULL_OPENCV']);

// Intrinsics of a frame's camera as {fx, fy, cx, cy, width, height}; a 60° 4:3 camera when
// the data has none.
function intrinsics(camera) {
  const width = camera?.width || 640;
  const height = camera?.height || 480;
  const params = camera?.params || [];
  const fx = camera?.focal_px ?? params[0] ?? width / (2 * Math.tan(Math.PI / 6));
  const fy = kTwoFocalModels.has(camera?.model) && isNumber(params[1]) ? params[1] : fx;
  const cx = camera?.cx ?? (kTwoFocalModels.has(camera?.model) ? params[2] : params[1]) ?? width / 2;
  const cy = camera?.cy ?? (kTwoFocalModels.has(camera?.model) ? params[3] : params[2]) ?? height / 2;
  return { fx, fy, cx, cy, width, height };
}

function median(values) {
  if (!values.length) return 0;
  const sorted = [...values].sort((a, b) => a - b);
  return sorted[Math.floor(sorted.length / 2)];
}

// Low and high percentiles of each axis of flat xyz values (outliers do not set the view).
function robustBox(xyz, lo = 0.02, hi = 0.98) {
  const n = Math.floor(xyz.length / 3);
  const step = Math.max(1, Math.floor(n / 20000));
  const axes = [[], [], []];
  for (let i = 0; i < n; i += step) for (let a = 0; a < 3; ++a) axes[a].push(xyz[3 * i + a]);
  const box = { min: new Vector3(), max: new Vector3() };
  axes.forEach((values, a) => {
    values.sort((p, q) => p - q);
    box.min.setComponent(a, values[Math.floor(lo * (values.length - 1))]);
    box.max.setComponent(a, values[Math.ceil(hi * (values.length - 1))]);
  });
  return box;
}

// Frustum of one frame in world coordinates: apex, the four image corners at `depth`, and
// the point halfway along its axis (where a click selects it).
function frustum(frame, camera, depth) {
  const k = intrinsics(camera);
  const r = frame.world_from_cam_rotation;
  const c = new Vector3(...frame.center);
  const toWorld = (x, y, z) =>
    new Vector3(r[0] * x + r[1] * y + r[2] * z, r[3] * x + r[4] * y + r[5] * z, r[6] * x + r[7] * y + r[8] * z).add(c);
  const corners = [[0, 0], [k.width, 0], [k.width, k.height], [0, k.height]].map(([u, v]) =>
    toWorld(((u - k.cx) / k.fx) * depth, ((v - k.cy) / k.fy) * depth, depth));
  const middle = toWorld(0, 0, depth / 2);
  return { apex: c, corners, middle };
}

// 8 edges (16 vertices) of a frustum as a flat array.
function frustumEdges(f) {
  const v = [];
  for (let i = 0; i < 4; ++i) v.push(f.apex, f.corners[i], f.corners[i], f.corners[(i + 1) % 4]);
  return v.flatMap((p) => [p.x, p.y, p.z]);
}

// 6 triangles of a closed frustum (4 sides, the image rectangle) as a flat array.
function frustumFaces(f) {
  const [a, b, c, d] = f.corners;
  const v = [f.apex, a, b, f.apex, b, c, f.apex, c, d, f.apex, d, a, a, b, c, a, c, d];
  return v.flatMap((p) => [p.x, p.y, p.z]);
}
const kTrianglesPerFrustum = 6;

// sRGB byte -> linear value, as three.js expects vertex colours.
const kLinearFromByte = Array.from({ length: 256 }, (_, i) => new Color().setRGB(i / 255, 0, 0, SRGBColorSpace).r);

function pointCloud(points) {
  const geometry = new BufferGeometry();
  geometry.setAttribute('position', new Float32BufferAttribute(points.xyz, 3));
  const n = Math.floor(points.xyz.length / 3);
  const colours = new Float32Array(3 * n).fill(0.5);
  if (Array.isArray(points.rgb) && points.rgb.length === 3 * n) {
    for (let i = 0; i < 3 * n; ++i) colours[i] = kLinearFromByte[points.rgb[i] & 255];
  }
  geometry.setAttribute('color', new Float32BufferAttribute(colours, 3));
  return new Points(geometry, new PointsMaterial({ size: 2, sizeAttenuation: false, vertexColors: true }));
}

function lineGeometry(flat) {
  const geometry = new BufferGeometry();
  geometry.setAttribute('position', new Float32BufferAttribute(flat, 3));
  return geometry;
}

function describe(frame) {
  const seen = isNumber(frame.num_points3D) ? `, ${fmt(frame.num_points3D)} points observed` : '';
  const of = isNumber(frame.num_points2D) ? ` of ${fmt(frame.num_points2D)} keypoints` : '';
  const model = isNumber(frame.model) ? ` (model ${frame.model})` : '';
  return `frame ${frame.index}: ${frame.name ?? ''}${seen}${of}${model}`;
}

// Builds the view in `parent`. Returns {canvas, cameraScreenPosition(index)}, or null when
// there is nothing to show.
export function scene3d(parent, data) {
  const cameras = new Map((data.cameras || []).map((c) => [c.camera_id, c]));
  const frames = (data.frames || []).filter((f) =>
    f.registered && (f.model ?? 0) === 0 && Array.isArray(f.center) && Array.isArray(f.world_from_cam_rotation));
  const xyz = data.points?.xyz || [];
  if (!frames.length && xyz.length < 3) return null;

  const label = el('p', { id: 'selected-camera', class: 'selected' }, 'click a camera (frustum) to see its frame');
  const container = el('div', { class: 'view3d' });
  parent.append(container, label);

  const renderer = new WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
  renderer.setPixelRatio(window.devicePixelRatio || 1);
  renderer.setClearColor(kBackground);
  container.append(renderer.domElement);
  const scene = new Scene();

  // Extent of the scene: the robust box of the points with the camera centres.
  const centres = frames.map((f) => new Vector3(...f.center));
  const box = xyz.length >= 3 ? robustBox(xyz) : { min: centres[0].clone(), max: centres[0].clone() };
  for (const c of centres) { box.min.min(c); box.max.max(c); }
  const diagonal = Math.max(box.max.distanceTo(box.min), 1e-9);
  const target = box.min.clone().add(box.max).multiplyScalar(0.5);

  // Frusta a fraction of the step between consecutive frames, within 1 % .. 6 % of the scene.
  const steps = centres.slice(1).map((c, i) => c.distanceTo(centres[i]));
  const depth = Math.min(Math.max(0.8 * median(steps) || 0.03 * diagonal, 0.01 * diagonal), 0.06 * diagonal);
  const frusta = frames.map((f) => frustum(f, cameras.get(f.camera_id), depth));

  if (xyz.length >= 3) scene.add(pointCloud(data.points));
  if (frusta.length) {
    scene.add(new LineSegments(lineGeometry(frusta.flatMap(frustumEdges)), new LineBasicMaterial({ color: kFrustumColour })));
  }
  if (centres.length >= 2) {
    scene.add(new Line(lineGeometry(centres.flatMap((c) => [c.x, c.y, c.z])), new LineBasicMaterial({ color: kPathColour })));
  }
  // Faint faces: what a click hits.
  const pickMesh = new Mesh(lineGeometry(frusta.flatMap(frustumFaces)),
    new MeshBasicMaterial({ color: kFrustumColour, transparent: true, opacity: 0.08, side: DoubleSide, depthWrite: false }));
  scene.add(pickMesh);
  const selected = new Mesh(new BufferGeometry(),
    new MeshBasicMaterial({ color: kSelectedColour, transparent: true, opacity: 0.6, side: DoubleSide, depthWrite: false }));
  const selectedEdges = new LineSegments(new BufferGeometry(), new LineBasicMaterial({ color: kSelectedColour }));
  // A marker of fixed size on screen at the selected camera's centre: a frustum alone can be a
  // few pixels on a long path.
  const selectedMarker = new Points(new BufferGeometry(),
    new PointsMaterial({ color: kSelectedColour, size: 12, sizeAttenuation: false, depthTest: false }));
  selectedMarker.renderOrder = 1;
  scene.add(selected, selectedEdges, selectedMarker);

  // Looking down the cameras' mean up direction, from above and to the side.
  const up = new Vector3();
  for (const f of frames) {
    const r = f.world_from_cam_rotation;
    up.add(new Vector3(-r[1], -r[4], -r[7]));  // world_from_cam * (0, -1, 0): image up
  }
  if (up.lengthSq() < 1e-12) up.set(0, -1, 0);
  up.normalize();
  const side = Math.abs(up.x) < 0.9 ? new Vector3(1, 0, 0) : new Vector3(0, 1, 0);
  side.sub(up.clone().multiplyScalar(side.dot(up))).normalize();
  const camera = new PerspectiveCamera(50, 2, diagonal * 1e-4, diagonal * 100);
  camera.up.copy(up);
  const distance = (0.4 * diagonal) / Math.sin((camera.fov * Math.PI) / 360);
  camera.position.copy(target).addScaledVector(up.clone().multiplyScalar(0.8).add(side.multiplyScalar(0.6)).normalize(), distance);
  const controls = new OrbitControls(camera, renderer.domElement);
  controls.target.copy(target);
  controls.update();

  const render = () => renderer.render(scene, camera);
  controls.addEventListener('change', render);
  const resize = () => {
    const width = container.clientWidth;
    const height = container.clientHeight;
    if (!width || !height) return;
    renderer.setSize(width, height);
    camera.aspect = width / height;
    camera.updateProjectionMatrix();
    render();
  };
  new ResizeObserver(resize).observe(container);
  resize();

  // Pixel position of a world point in the canvas (CSS pixels), null when behind the camera.
  const toCanvas = (p) => {
    const ndc = p.clone().project(camera);
    if (ndc.z < -1 || ndc.z > 1) return null;
    const rect = renderer.domElement.getBoundingClientRect();
    return { x: ((ndc.x + 1) / 2) * rect.width, y: ((1 - ndc.y) / 2) * rect.height };
  };

  const select = (k) => {
    const f = frusta[k];
    selected.geometry.dispose();
    selected.geometry = lineGeometry(frustumFaces(f));
    selectedEdges.geometry.dispose();
    selectedEdges.geometry = lineGeometry(frustumEdges(f));
    selectedMarker.geometry.dispose();
    selectedMarker.geometry = lineGeometry([centres[k].x, centres[k].y, centres[k].z]);
    label.textContent = describe(frames[k]);
    render();
  };

  // A click selects, among the frusta under the pointer, the one whose middle is nearest to
  // it; a click near no frustum but within 12 px of a frustum's middle selects that one.
  const raycaster = new Raycaster();
  let downAt = null;
  renderer.domElement.addEventListener('pointerdown', (e) => { downAt = { x: e.clientX, y: e.clientY }; });
  renderer.domElement.addEventListener('pointerup', (e) => {
    if (!downAt || Math.hypot(e.clientX - downAt.x, e.clientY - downAt.y) > 4) return;  // a drag
    const rect = renderer.domElement.getBoundingClientRect();
    const click = { x: e.clientX - rect.left, y: e.clientY - rect.top };
    raycaster.setFromCamera(new Vector2((click.x / rect.width) * 2 - 1, 1 - (click.y / rect.height) * 2), camera);
    const hit = new Set(raycaster.intersectObject(pickMesh).map((h) => Math.floor(h.faceIndex / kTrianglesPerFrustum)));
    let best = -1;
    let bestDistance = Infinity;
    frusta.forEach((f, k) => {
      const p = toCanvas(f.middle);
      if (!p) return;
      const d = Math.hypot(p.x - click.x, p.y - click.y);
      if ((hit.has(k) || d < 12) && d < bestDistance) [best, bestDistance] = [k, d];
    });
    if (best >= 0) select(best);
  });

  return {
    canvas: renderer.domElement,
    // Page position (CSS pixels) of the middle of frame `index`'s frustum, null when it is
    // not drawn or not in view.
    cameraScreenPosition(index) {
      const k = frames.findIndex((f) => f.index === index);
      const p = k >= 0 ? toCanvas(frusta[k].middle) : null;
      const rect = renderer.domElement.getBoundingClientRect();
      if (!p || p.x < 0 || p.y < 0 || p.x > rect.width || p.y > rect.height) return null;
      return { x: rect.left + window.scrollX + p.x, y: rect.top + window.scrollY + p.y };
    },
  };
}
