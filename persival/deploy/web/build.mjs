// Builds the viewer into dist/: one bundled module, the page, onnxruntime-web's WebAssembly
// runtime and the pose tracker's files copied next to it (the page never reaches a CDN).
import { build } from 'esbuild';
import { cpSync, mkdirSync, rmSync, copyFileSync } from 'node:fs';

const out = 'dist';
rmSync(out, { recursive: true, force: true });
mkdirSync(`${out}/ort`, { recursive: true });
await build({
  entryPoints: ['src/main.js'],
  bundle: true,
  format: 'esm',
  minify: true,
  sourcemap: true,
  target: ['es2022'],
  outfile: `${out}/app.js`,
  // the runtime variant that loads its .mjs/.wasm from env.wasm.wasmPaths (served by us)
  conditions: ['onnxruntime-web-use-extern-wasm'],
  logLevel: 'warning',
});
for (const f of ['ort-wasm-simd-threaded.mjs', 'ort-wasm-simd-threaded.wasm']) {
  copyFileSync(`node_modules/onnxruntime-web/dist/${f}`, `${out}/ort/${f}`);
}
// The pose tracker for the live webcam (MediaPipe Pose, its full landmark model): loaded by the
// page only when the webcam is switched on, from our own server (works offline). The SIMD build
// only: every current browser runs WebAssembly SIMD.
mkdirSync(`${out}/mediapipe`, { recursive: true });
for (const f of ['pose.js', 'pose_solution_packed_assets_loader.js', 'pose_solution_packed_assets.data',
  'pose_solution_simd_wasm_bin.js', 'pose_solution_simd_wasm_bin.wasm', 'pose_solution_simd_wasm_bin.data',
  'pose_web.binarypb', 'pose_landmark_full.tflite']) {
  copyFileSync(`node_modules/@mediapipe/pose/${f}`, `${out}/mediapipe/${f}`);
}
cpSync('index.html', `${out}/index.html`);
cpSync('src/style.css', `${out}/style.css`);
console.log('built', out);
