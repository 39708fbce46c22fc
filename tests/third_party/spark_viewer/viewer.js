// See index.html. Reports progress and errors to /log, the finished frame to /result.
import * as THREE from 'three';
import { SparkRenderer, SplatMesh } from '@sparkjsdev/spark';

const log = (text) => fetch('/log', { method: 'POST', body: String(text) });

async function main() {
  const cam = await (await fetch('/camera.json')).json();
  const canvas = document.getElementById('view');
  const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
  renderer.setPixelRatio(1);
  renderer.setSize(cam.width, cam.height, false);
  renderer.setClearColor(new THREE.Color().setRGB(...cam.background, THREE.SRGBColorSpace), 1);

  const scene = new THREE.Scene();
  // The original 3DGS rasterizer's conventions, which ours follows: 0.3 px^2 added to the screen
  // covariance without opacity compensation, splats sorted by view depth.
  const spark = new SparkRenderer({ renderer, preBlurAmount: 0.3, blurAmount: 0, sortRadial: false,
                                    enableLod: false });
  scene.add(spark);
  const splats = new SplatMesh({ url: '/model.ply', lod: false });
  await splats.initialized;
  scene.add(splats);
  log(`loaded ${splats.packedSplats ? splats.packedSplats.numSplats : '?'} splats`);

  const camera = new THREE.PerspectiveCamera();
  camera.matrixAutoUpdate = false;
  camera.matrix.fromArray(cam.camera_to_world);
  camera.updateMatrixWorld(true);
  // Pinhole intrinsics as an OpenGL projection (pixel rows grow downwards, NDC y upwards).
  const { width: w, height: h, fx, fy, cx, cy } = cam;
  const n = cam.near, f = cam.far;
  camera.projectionMatrix.set(
      2 * fx / w, 0, 1 - 2 * cx / w, 0,
      0, 2 * fy / h, 2 * cy / h - 1, 0,
      0, 0, -(f + n) / (f - n), -2 * f * n / (f - n),
      0, 0, -1, 0);
  camera.projectionMatrixInverse.copy(camera.projectionMatrix).invert();

  // Render frames until the sort has caught up with the camera (it runs in a worker).
  for (let frame = 0; frame < cam.frames; ++frame) {
    renderer.render(scene, camera);
    await new Promise((resolve) => requestAnimationFrame(resolve));
    await new Promise((resolve) => setTimeout(resolve, 50));
  }
  renderer.render(scene, camera);
  await fetch('/result', { method: 'POST', body: canvas.toDataURL('image/png') });
}
main().catch((e) => log(`error: ${e && e.stack ? e.stack : e}`));
