// The player inlined into the page that `gma export avatar.gma page.html` writes.
//
// The page holds the avatar's surfels at rest (its own shape, bones at identity), each surfel's four
// bones and weights, and per motion the bones' rest->posed transforms of every frame. Spark skins the
// surfels on the GPU (SplatSkinning) and renders them as 2D Gaussians; this file only decodes the data,
// feeds bone transforms for the current time and wires the controls.
//
// Hooks: `#t=SECONDS` shows that moment, paused; `window.gmaReady` becomes true once a frame with the
// avatar has been drawn; `window.gmaFps` is the measured frame rate, `window.gmaFrames` counts frames.
import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { PackedSplats, SparkRenderer, SplatMesh, SplatSkinning, SplatSkinningMode } from "@sparkjsdev/spark";

const meta = JSON.parse(document.getElementById("gma-meta").textContent);

async function readBlob() {
  const text = document.getElementById("gma-data").textContent.trim();
  const packed = Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
  const stream = new Blob([packed]).stream().pipeThrough(new DecompressionStream("gzip"));
  return new Response(stream).arrayBuffer();
}

const TYPED = { f32: Float32Array, u16: Uint16Array, u8: Uint8Array };

function view(buffer, spec) {
  const count = spec.shape.reduce((a, b) => a * b, 1);
  return new TYPED[spec.dtype](buffer, spec.offset, count);
}

function buildSplats(buffer) {
  const n = meta.numSplats;
  const a = Object.fromEntries(Object.entries(meta.arrays).map(([k, spec]) => [k, view(buffer, spec)]));
  const packed = new PackedSplats({ maxSplats: n });
  const center = new THREE.Vector3(), scales = new THREE.Vector3(), quat = new THREE.Quaternion();
  const color = new THREE.Color();
  for (let i = 0; i < n; i++) {
    center.fromArray(a.means, 3 * i);
    scales.fromArray(a.scales, 3 * i);
    quat.fromArray(a.quats, 4 * i); // x, y, z, w
    color.fromArray(a.colors, 3 * i);
    packed.pushSplat(center, scales, quat, a.opacities[i], color);
  }
  return { packed, skin: a.skin, motions: meta.motions.map((m) => view(buffer, m.bones)) };
}

function makeCamera(width, height) {
  const c = meta.camera;
  const camera = new THREE.PerspectiveCamera(c.fovY, width / height, 0.01, 100);
  camera.up.fromArray(c.up);
  camera.position.fromArray(c.eye);
  camera.lookAt(new THREE.Vector3().fromArray(c.target));
  return camera;
}

function parseFragment() {
  const match = /(?:^#|&)t=([0-9.]+)/.exec(window.location.hash);
  return match ? Math.max(0, parseFloat(match[1])) : null;
}

class Player {
  constructor(skinning, motions) {
    this.skinning = skinning;
    this.motions = motions;
    this.index = 0;
    this.time = 0;
    this.playing = true;
    this.quat = new THREE.Quaternion();
    this.pos = new THREE.Vector3();
  }

  get motion() { return meta.motions[this.index]; }
  get duration() { return this.motion.frames / this.motion.fps; }

  frameAt(time) {
    return Math.min(this.motion.frames - 1, Math.round(time * this.motion.fps));
  }

  // Bones of the current frame: per bone a quaternion (x, y, z, w) and a translation. Spark regenerates
  // the splats when bones change, so an unchanged frame (paused, or between motion frames) is skipped.
  apply() {
    const key = `${this.index}:${this.frameAt(this.time)}`;
    if (key === this.applied) return;
    this.applied = key;
    const bones = this.motions[this.index];
    const numBones = meta.numBones;
    const base = this.frameAt(this.time) * numBones * 7;
    for (let j = 0; j < numBones; j++) {
      this.quat.fromArray(bones, base + 7 * j);
      this.pos.fromArray(bones, base + 7 * j + 4);
      this.skinning.setBoneQuatPos(j, this.quat, this.pos);
    }
    this.skinning.updateBones();
  }

  advance(seconds) {
    if (!this.playing) return;
    this.time = (this.time + seconds) % this.duration;
  }
}

function wireControls(player) {
  const play = document.getElementById("play");
  const slider = document.getElementById("time");
  const clock = document.getElementById("clock");
  const picker = document.getElementById("motion");
  meta.motions.forEach((m, i) => picker.add(new Option(m.name, String(i))));
  picker.hidden = meta.motions.length < 2;
  play.onclick = () => { player.playing = !player.playing; };
  slider.oninput = () => { player.playing = false; player.time = Number(slider.value) * player.duration; };
  picker.onchange = () => { player.index = Number(picker.value); player.time = 0; };
  return () => {
    play.textContent = player.playing ? "pause" : "play";
    if (document.activeElement !== slider) slider.value = String(player.time / player.duration);
    clock.textContent = `${player.time.toFixed(2)} / ${player.duration.toFixed(2)} s`;
  };
}

function fpsCounter() {
  const label = document.getElementById("fps");
  let frames = 0, since = performance.now();
  window.gmaFrames = 0;
  return () => {
    frames++;
    window.gmaFrames++;
    const now = performance.now();
    if (now - since >= 1000) {
      window.gmaFps = (1000 * frames) / (now - since);
      label.textContent = `${window.gmaFps.toFixed(1)} FPS`;
      frames = 0;
      since = now;
    }
  };
}

async function main() {
  const canvas = document.getElementById("view");
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(canvas.clientWidth, canvas.clientHeight, false);
  renderer.setClearColor(new THREE.Color().fromArray(meta.background), 1);
  const scene = new THREE.Scene();
  const camera = makeCamera(canvas.clientWidth, canvas.clientHeight);
  const spark = new SparkRenderer({
    renderer, enable2DGS: meta.enable2DGS, maxStdDev: meta.maxStdDev,
  });
  scene.add(spark);

  const { packed, skin, motions } = buildSplats(await readBlob());
  const mesh = new SplatMesh({ packedSplats: packed });
  await mesh.initialized;
  const skinning = new SplatSkinning({
    mesh, numSplats: meta.numSplats, numBones: meta.numBones, mode: SplatSkinningMode.DUAL_QUATERNION,
  });
  skinning.skinData.set(skin);
  skinning.skinTexture.needsUpdate = true;
  mesh.skinning = skinning;
  mesh.updateGenerator();
  scene.add(mesh);

  const controls = new OrbitControls(camera, canvas);
  controls.target.fromArray(meta.camera.target);
  controls.update();
  window.addEventListener("resize", () => {
    renderer.setSize(canvas.clientWidth, canvas.clientHeight, false);
    camera.aspect = canvas.clientWidth / canvas.clientHeight;
    camera.updateProjectionMatrix();
  });

  const player = new Player(skinning, motions);
  const applyFragment = () => {
    const t = parseFragment();
    if (t !== null) { player.playing = false; player.time = Math.min(t, player.duration); }
  };
  applyFragment();
  window.addEventListener("hashchange", applyFragment);
  window.gmaPlayer = player;
  const showState = wireControls(player);
  const countFrame = fpsCounter();

  player.apply();
  // Spark generates and sorts the splats asynchronously; wait for both before calling the frame drawn.
  await spark.update({ scene, camera });
  await spark.update({ scene, camera });
  let last = performance.now();
  renderer.setAnimationLoop(() => {
    const now = performance.now();
    player.advance((now - last) / 1000);
    last = now;
    player.apply();
    controls.update();
    // Spark draws nothing until its first sort of the generated splats has finished.
    const drawsAvatar = spark.activeSplats > 0 && spark.orderingTexture;
    renderer.render(scene, camera);
    showState();
    countFrame();
    if (drawsAvatar) window.gmaReady = true;
  });
}

main().catch((error) => {
  document.getElementById("error").textContent = `Could not play the avatar: ${error.message}`;
  window.gmaError = String(error && error.stack || error);
  throw error;
});
