// Validates glTF files with the Khronos glTF validator; exits 1 on any error or warning.
//   node validate.mjs FILE.glb...
import fs from 'fs';
import validator from 'gltf-validator';

let bad = 0;
for (const f of process.argv.slice(2)) {
  const r = await validator.validateBytes(new Uint8Array(fs.readFileSync(f)));
  const i = r.issues;
  console.log(`${f}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos, ${i.numHints} hints ` +
    `(${r.info.drawCallCount} draw calls, ${r.info.totalVertexCount} vertices, extensions used: ${(r.info.extensionsUsed || []).join(', ')})`);
  // Errors and warnings in full; infos (e.g. TEXCOORD_0, written for texturing but not used
  // by the baked materials) and hints only counted.
  for (const m of i.messages.filter(m => m.severity <= 1).slice(0, 20)) {
    console.log(`  ${['error', 'warning', 'info', 'hint'][m.severity]} ${m.code} at ${m.pointer || '-'}: ${m.message}`);
  }
  if (i.numErrors + i.numWarnings > 0) bad++;
}
process.exit(bad ? 1 : 0);
