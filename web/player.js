// An avatar's .glb played with three.js: one slider per morph target (the studio's expression names), the jaw
// joint's opening in degrees, the file's first animation played and paused, an orbit camera. window.player is the
// page's interface for scripts (the project's tests and its documentation's pictures use it).
import * as THREE from 'three';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const EXPRESSION_RANGE = [-1.0, 1.5];  // the studio's expression sliders (app/animation.py SLIDER_RANGES)
const JAW_RANGE_DEG = [-5.0, 30.0];
const FOV_Y_DEG = 25;

const view = document.getElementById('view');
const status = document.getElementById('status');
const renderer = new THREE.WebGLRenderer({ antialias: true, alpha: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
renderer.setClearColor(0x000000, 0);  // transparent: the page shows behind, read-backs carry the silhouette
view.appendChild(renderer.domElement);
const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(FOV_Y_DEG, 1, 0.01, 100);
const controls = new OrbitControls(camera, renderer.domElement);
const clock = new THREE.Clock();
let mesh = null, jaw = null, mixer = null, action = null, playing = false, fixedView = false, dirty = true;
const sliders = {};

function fit() {
  if (fixedView) return;
  const w = view.clientWidth, h = view.clientHeight;
  renderer.setSize(w, h);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  dirty = true;
}

function slider(parent, name, label, [lo, hi], step, onInput) {
  const row = document.createElement('div');
  row.className = 'slider';
  row.innerHTML = `<label for="s-${name}">${label}</label><input id="s-${name}" type="range" min="${lo}" `
    + `max="${hi}" step="${step}" value="0"><output>0.00</output>`;
  const input = row.querySelector('input'), out = row.querySelector('output');
  input.addEventListener('input', () => { out.value = Number(input.value).toFixed(2); onInput(Number(input.value)); });
  parent.appendChild(row);
  return { input, out, show(v) { input.value = v; out.value = Number(v).toFixed(2); } };
}

function setWeight(name, value) {
  const k = mesh.morphTargetDictionary[name];
  if (k === undefined) throw new Error(`no morph target named ${name}`);
  mesh.morphTargetInfluences[k] = value;
  sliders[name].show(value);
  dirty = true;
}

function setJawDeg(deg) {
  if (!jaw) throw new Error('this avatar has no jaw joint');
  jaw.quaternion.setFromAxisAngle(new THREE.Vector3(1, 0, 0), THREE.MathUtils.degToRad(deg));
  sliders['jaw open'].show(deg);
  dirty = true;
}

function showControls() {  // the sliders follow what the animation sets
  for (const [name, k] of Object.entries(mesh.morphTargetDictionary)) sliders[name].show(mesh.morphTargetInfluences[k]);
  if (jaw) {
    const angle = 2 * Math.acos(Math.min(1, Math.abs(jaw.quaternion.w))) * Math.sign(jaw.quaternion.x || 1);
    sliders['jaw open'].show(THREE.MathUtils.radToDeg(angle));
  }
  const time = document.getElementById('time');
  time.value = action.time / action.getClip().duration;
  document.getElementById('time-out').value = action.time.toFixed(2);
}

function setPlaying(on) {
  if (!action) return;
  playing = on;
  document.getElementById('play').textContent = on ? 'pause' : 'play';
  if (on) { action.paused = false; action.play(); clock.getDelta(); }
  else action.paused = true;
}

function seek(seconds) {  // the animation at that time, paused
  setPlaying(false);
  action.paused = false;  // a paused action's time stands still through setTime
  action.play();
  mixer.setTime(seconds);
  action.paused = true;
  showControls();
  dirty = true;
}

function neutral() {
  setPlaying(false);
  if (action) { action.stop(); document.getElementById('time').value = 0; }
  for (const name of Object.keys(mesh.morphTargetDictionary)) setWeight(name, 0);
  if (jaw) setJawDeg(0);
}

function frameHead() {
  const box = new THREE.Box3().setFromObject(scene);
  const centre = box.getCenter(new THREE.Vector3());
  const radius = box.getSize(new THREE.Vector3()).length() / 2;
  const distance = 1.05 * radius / Math.sin(THREE.MathUtils.degToRad(FOV_Y_DEG / 2));
  camera.position.set(centre.x, centre.y, centre.z + distance);
  camera.near = distance / 20;
  camera.far = distance * 20;
  controls.target.copy(centre);
  controls.update();
  fit();
}

// Row-major 4x4 (16 numbers), as numpy writes them.
const matrix = (m) => new THREE.Matrix4().set(...m);

// Shows the head through a given camera: view (world to camera) and projection (OpenGL clip from camera), both
// row-major, on a width x height canvas; the orbit camera takes over again at the next drag.
function setView(viewMatrix, projection, width, height) {
  fixedView = true;
  renderer.setSize(width, height);
  matrix(viewMatrix).invert().decompose(camera.position, camera.quaternion, camera.scale);
  camera.updateMatrixWorld();
  camera.projectionMatrix.copy(matrix(projection));
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();
  const distance = camera.position.distanceTo(controls.target);  // the orbit's centre: as far ahead as it was
  const forward = new THREE.Vector3(0, 0, -1).applyQuaternion(camera.quaternion);
  controls.target.copy(camera.position).addScaledVector(forward, distance);
  dirty = true;
}

// The canvas as a PNG data URL, drawn now.
function snapshot() {
  scene.updateMatrixWorld();
  renderer.render(scene, camera);
  dirty = false;
  return renderer.domElement.toDataURL('image/png');
}

function loop() {
  requestAnimationFrame(loop);
  const dt = clock.getDelta();
  if (playing) { mixer.update(dt); showControls(); dirty = true; }
  if (dirty) { renderer.render(scene, camera); dirty = false; }
}

async function load(url) {
  const gltf = await new GLTFLoader().loadAsync(url);
  scene.add(gltf.scene);
  gltf.scene.traverse((o) => { if (!mesh && o.isMesh && o.morphTargetDictionary) mesh = o; });
  if (!mesh) throw new Error(`${url}: no mesh with morph targets`);
  jaw = gltf.scene.getObjectByName('jaw') || null;
  const names = Object.keys(mesh.morphTargetDictionary);
  const jawBox = document.getElementById('jaw');
  if (jaw) sliders['jaw open'] = slider(jawBox, 'jaw', 'jaw open (deg)', JAW_RANGE_DEG, 0.1, setJawDeg);
  else jawBox.textContent = 'no jaw joint';
  const box = document.getElementById('expressions');
  for (const name of names) sliders[name] = slider(box, name, name, EXPRESSION_RANGE, 0.01, (v) => setWeight(name, v));
  if (gltf.animations.length) {
    mixer = new THREE.AnimationMixer(gltf.scene);
    action = mixer.clipAction(gltf.animations[0]);
    const play = document.getElementById('play'), time = document.getElementById('time');
    play.disabled = time.disabled = false;
    play.addEventListener('click', () => setPlaying(!playing));
    time.addEventListener('input', () => seek(time.value * action.getClip().duration));
  }
  document.getElementById('reset').addEventListener('click', neutral);
  frameHead();
  const clip = action ? `animation '${action.getClip().name}', ${action.getClip().duration.toFixed(1)} s` : 'no animation';
  status.textContent = `${url}\n${names.length} expressions, ${clip}\nthree.js r${THREE.REVISION}`;
  return { morphs: names, jaw: !!jaw, animation: action ? action.getClip().name : null,
           duration: action ? action.getClip().duration : 0 };
}

window.addEventListener('resize', fit);
controls.addEventListener('change', () => { dirty = true; });
const file = new URLSearchParams(location.search).get('glb') || 'avatar.glb';
const ready = load(file).catch((e) => { status.textContent = `could not open ${file}: ${e.message}`; throw e; });
window.player = { ready, setWeight, setJawDeg, setPlaying, seek, neutral, setView, snapshot };
loop();
