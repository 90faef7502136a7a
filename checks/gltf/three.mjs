// Opens a baked GLB in three.js in headless Chromium (Playwright, Debian's chromium), renders
// it from the GLB's camera, and compares the screenshot with our own render of the same
// view (a PNG at the same exposure) in linear light. three.js draws SS × SS times larger
// without antialiasing and the pixels are averaged in linear light (a box filter, as our
// renderer's samples per pixel).
//   node three.mjs SCENE.glb OURS.png OUT.png [MAX_RMSE] [colors|lightmap|moz|moz-textured|uniform:L]
// Prints the relative RMSE; exits 1 above MAX_RMSE (default 0.08), when three.js did not
// use the vertex colours (or the lightmap on TEXCOORD_1: as emissive texture, or as
// MOZ_lightmap for `moz`; `moz-textured` also needs a base-colour texture), or on any
// error. `colors`, `lightmap` and `moz` also fail when more than 0.1 % of the pixels are darker than half of ours
// (black texels showing through); `uniform:L` (a furnace, where every surface has one
// radiance) fails when any pixel is more than 2 % off L: a seam, an unfilled texel or
// a texel bled from another chart shows at once.
import http from 'http';
import fs from 'fs';
import path from 'path';
import { fileURLToPath } from 'url';
import { chromium } from 'playwright-core';
import { PNG } from 'pngjs';

const [glb, ours, out, maxArg, modeArg] = process.argv.slice(2);
const mode = modeArg || 'colors';
const max = maxArg ? +maxArg : 0.08;
const SS = 4;
const here = path.dirname(fileURLToPath(import.meta.url));
const ref = PNG.sync.read(fs.readFileSync(ours));
const types = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.glb': 'model/gltf-binary' };
const server = http.createServer((req, res) => {
  const u = new URL(req.url, 'http://x').pathname;
  // The MOZ_lightmap loader plugin is the viewer's own.
  const plugin = path.join(here, '..', '..', 'viewer', 'moz_lightmap.mjs');
  const file = u === '/scene.glb' ? glb : u === '/moz_lightmap.mjs' ? plugin : path.join(here, path.normalize(u));
  if (!file.startsWith(here) && file !== glb && file !== plugin) { res.writeHead(403); return res.end(); }
  fs.readFile(file, (err, data) => {
    if (err) { res.writeHead(404); return res.end(); }
    res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
    res.end(data);
  });
});
await new Promise(r => server.listen(0, '127.0.0.1', r));
const port = server.address().port;
const exe = process.env.CHROMIUM || '/usr/bin/chromium';
const browser = await chromium.launch({ executablePath: exe, args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--no-sandbox'] });
let status = 0;
try {
  const page = await browser.newPage();
  page.on('console', m => { if (m.type() === 'error') console.log('page:', m.text()); });
  await page.goto(`http://127.0.0.1:${port}/page.html?w=${SS * ref.width}&h=${SS * ref.height}`);
  await page.waitForFunction(() => window.result || window.error, null, { timeout: 120000 });
  const err = await page.evaluate(() => window.error);
  if (err) throw new Error(err);
  const info = await page.evaluate(() => window.info);
  const data = await page.evaluate(() => window.result);
  const big = PNG.sync.read(Buffer.from(data.split(',')[1], 'base64'));
  const lin = v => { v /= 255; return v <= 0.04045 ? v / 12.92 : Math.pow((v + 0.055) / 1.055, 2.4); };
  const enc = v => { v = Math.min(Math.max(v, 0), 1); return Math.round(255 * (v <= 0.0031308 ? 12.92 * v : 1.055 * Math.pow(v, 1 / 2.4) - 0.055)); };
  // Box-filter SS × SS in linear light.
  const W = ref.width, H = ref.height;
  const small = new Float64Array(W * H * 3);
  for (let y = 0; y < H * SS; y++) {
    for (let x = 0; x < W * SS; x++) {
      const i = 4 * (y * W * SS + x), o = 3 * (Math.floor(y / SS) * W + Math.floor(x / SS));
      for (let c = 0; c < 3; c++) small[o + c] += lin(big.data[i + c]) / (SS * SS);
    }
  }
  const img = new PNG({ width: W, height: H });
  for (let p = 0; p < W * H; p++) {
    for (let c = 0; c < 3; c++) img.data[4 * p + c] = enc(small[3 * p + c]);
    img.data[4 * p + 3] = 255;
  }
  fs.writeFileSync(out, PNG.sync.write(img));
  // The project's image metric (../shared/reference/README.md): RMSE / mean of the
  // reference over all three channels, "light masked": pixels with a channel at or above 1
  // (here: clipped by the exposure, 255) and the 1-pixel ring around them are left out.
  // Averaging then clipping (ours) and clipping then averaging (three.js's vertex colours)
  // differ only there: a pixel that is a quarter lamp is white in ours.
  const sat = new Uint8Array(W * H);
  for (let p = 0; p < W * H; p++) {
    if (ref.data[4 * p] === 255 || ref.data[4 * p + 1] === 255 || ref.data[4 * p + 2] === 255) sat[p] = 1;
  }
  const masked = p => {
    const x = p % W, y = Math.floor(p / W);
    for (let dy = -1; dy <= 1; dy++) for (let dx = -1; dx <= 1; dx++) {
      const xx = x + dx, yy = y + dy;
      if (xx >= 0 && yy >= 0 && xx < W && yy < H && sat[yy * W + xx]) return true;
    }
    return false;
  };
  const metric = useMask => {
    let se = 0, sum = 0, n = 0;
    for (let p = 0; p < W * H; p++) {
      if (useMask && masked(p)) continue;
      for (let c = 0; c < 3; c++) {
        const a = small[3 * p + c], b = lin(ref.data[4 * p + c]);
        se += (a - b) * (a - b);
        sum += b;
        n++;
      }
    }
    return Math.sqrt(se / n) / Math.max(sum / n, 1e-30);
  };
  const all = metric(false), rmse = metric(true);
  // Dark texels showing through (unfilled or black lightmap texels along chart borders):
  // pixels at less than half of our render's luminance where ours is not dark.
  const lum = (v, p) => 0.2126 * v(p, 0) + 0.7152 * v(p, 1) + 0.0722 * v(p, 2);
  const oursL = p => lum((q, c) => lin(ref.data[4 * q + c]), p), theirsL = p => lum((q, c) => small[3 * q + c], p);
  let meanL = 0;
  for (let p = 0; p < W * H; p++) meanL += oursL(p) / (W * H);
  let dark = 0;
  for (let p = 0; p < W * H; p++) {
    if (!masked(p) && oursL(p) > 0.1 * meanL && theirsL(p) < 0.5 * oursL(p)) dark++;
  }
  console.log(`three.js r${info.three}: ${info.unlit} unlit meshes, ${info.vertexColors} with vertex colours, ` +
    `${info.lightmaps} with the lightmap on TEXCOORD_1 as emissive texture, ${info.moz} as MOZ_lightmap, ${info.textured} textured; ` +
    `relative RMSE against ${path.basename(ours)} ${(100 * rmse).toFixed(2)} % light masked (limit ${(100 * max).toFixed(1)} %), ` +
    `${(100 * all).toFixed(2)} % unmasked; ${dark} pixels darker than half of ours -> ${out}`);
  const used = mode === 'colors' ? info.unlit > 0 && info.vertexColors > 0
    : mode === 'moz' ? info.moz > 0 && info.vertexColors === 0
    : mode === 'moz-textured' ? info.moz > 0 && info.textured > 0 && info.vertexColors === 0
    : info.lightmaps > 0;
  if (!(rmse <= max) || !used || dark > 0.001 * W * H) status = 1;
  if (mode.startsWith('uniform:')) {
    const want = +mode.slice(8);
    let off = 0, worst = 0;
    for (let p = 0; p < W * H; p++) {
      for (let c = 0; c < 3; c++) {
        const d = Math.abs(small[3 * p + c] - want) / want;
        worst = Math.max(worst, d);
        if (d > 0.02) off++;
      }
    }
    console.log(`uniform ${want}: ${off} pixel channels more than 2 % off, worst ${(100 * worst).toFixed(2)} %`);
    if (off > 0) status = 1;
  }
} catch (e) {
  console.log(`three.js check error: ${e.message}`);
  status = 1;
} finally {
  await browser.close();
  server.close();
}
process.exit(status);
