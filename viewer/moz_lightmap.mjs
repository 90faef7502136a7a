// A GLTFLoader plugin for MOZ_lightmap (`radiosity bake --lightmap --lightmap-mode moz`;
// Mozilla Hubs' convention, which three.js's GLTFLoader does not read): the texture becomes
// the material's lightMap on its texCoord, read as linear data (as Hubs does), times its
// intensity, on a Lambert material, which shows base colour × lightMap × intensity / π — the
// diffuse light the bake computed (the standard material would keep a few per cent for its
// specular layer). Used by viewer/index.html and the check page checks/gltf/page.html.
//   import { mozLightmap } from './moz_lightmap.mjs';  loader.register(mozLightmap);
import * as THREE from 'three';

export function mozLightmap(parser) {
  const moz = i => { const d = parser.json.materials[i]; return d && d.extensions && d.extensions.MOZ_lightmap; };
  return {
    name: 'MOZ_lightmap',
    getMaterialType(i) { return moz(i) ? THREE.MeshLambertMaterial : null; },
    async extendMaterialParams(i, params) {
      const ext = moz(i);
      if (!ext) return;
      delete params.metalness;
      delete params.roughness;
      const tex = await parser.getDependency('texture', ext.index);
      tex.channel = ext.texCoord === undefined ? 1 : ext.texCoord;
      params.lightMap = tex;
      params.lightMapIntensity = ext.intensity === undefined ? 1 : ext.intensity;
    },
  };
}
