// Builds the viewer into dist/: one bundled module, the page, and onnxruntime-web's WebAssembly
// runtime copied next to it (the page never reaches a CDN).
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
cpSync('index.html', `${out}/index.html`);
cpSync('src/style.css', `${out}/style.css`);
console.log('built', out);
