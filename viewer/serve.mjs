// Serves the viewer page and one baked GLB (as /scene.glb) on localhost.
//   npm install && node serve.mjs ../cornell.glb [PORT]
import http from 'http';
import fs from 'fs';
import path from 'path';
import { fileURLToPath } from 'url';

const here = path.dirname(fileURLToPath(import.meta.url));
const [glb, portArg] = process.argv.slice(2);
if (glb && !fs.existsSync(glb)) {
  console.error(`${glb}: no such file (bake one with: radiosity bake -o scene.glb)`);
  process.exit(2);
}
if (!fs.existsSync(path.join(here, 'node_modules', 'three'))) {
  console.error(`three.js is not installed here: run  npm install  in ${here}`);
  process.exit(2);
}
const types = { '.html': 'text/html', '.js': 'text/javascript', '.mjs': 'text/javascript', '.glb': 'model/gltf-binary' };
const server = http.createServer((req, res) => {
  let u = decodeURIComponent(new URL(req.url, 'http://x').pathname);
  if (u === '/') u = '/index.html';
  const file = u === '/scene.glb' && glb ? path.resolve(glb) : path.join(here, path.normalize(u));
  if (file !== path.resolve(glb || '') && !file.startsWith(here + path.sep)) { res.writeHead(403); return res.end(); }
  fs.readFile(file, (err, data) => {
    if (err) { res.writeHead(404); return res.end(); }
    res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
    res.end(data);
  });
});
const port = +(portArg || 8080);
server.listen(port, '127.0.0.1', () => console.log(`radiosity viewer: http://127.0.0.1:${port}/  (${glb || 'drop a .glb on the page'}; Ctrl-C stops)`));
