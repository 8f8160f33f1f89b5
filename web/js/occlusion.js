// Labels behind the splats. The overlay draws over the scene, so a point's marker and label
// would show through a building; CesiumJS cannot pick splats, so the server answers from the
// splats' depth (POST /api/scenes/{scene}/visible): once the camera rests, every labelled
// marker in view is tested along the ray from the camera to it, and the hidden ones are drawn
// faint (overlay.js: hiddenKeys). Frames: rendered ECEF (metres).

import { api } from "./api.js";

/** The camera rests this long (ms) before the labels in view are tested. */
const REST_MS = 300;
/** Most markers tested at once (the server's limit). */
const MAX_POINTS = 200;

/** Test the labelled markers of `overlay` after each camera rest and each change of the
 *  drawing. `ctx`: {viewer, state, modelMatrix}. Returns {check} (tests call it). */
export function installOcclusion(ctx, overlay) {
  const { viewer } = ctx;
  const occ = { checks: 0, asked: 0, checkedPose: null };
  let timer = null;
  let seq = 0;

  const later = () => {
    clearTimeout(timer);
    timer = setTimeout(check, REST_MS);
  };

  const poseKey = () => {
    const p = viewer.camera.positionWC;
    const v = viewer.camera.directionWC;
    return [p.x, p.y, p.z, v.x, v.y, v.z].map((x) => x.toFixed(4)).join(",");
  };

  async function check() {
    const my = ++seq;
    const at = poseKey();
    const name = ctx.state.sceneName;
    const info = (ctx.state.scenes || []).find((s) => s.name === name);
    const cam = viewer.camera;
    const c = cam.positionWC;
    const d = cam.directionWC;
    // the labelled markers in front of the camera (a marker behind it is not drawn)
    const items = overlay.labelled().filter((m) => (m.position[0] - c.x) * d.x
      + (m.position[1] - c.y) * d.y + (m.position[2] - c.z) * d.z > 0).slice(0, MAX_POINTS);
    if (!name || !info || info.tiles_url || info.error || !items.length) {
      overlay.setHidden(new Set());
      occ.checks++;
      occ.checkedPose = at;
      return;
    }
    occ.asked++;
    try {
      const res = await api("POST", `/scenes/${encodeURIComponent(name)}/visible`, {
        origin: [c.x, c.y, c.z], points: items.map((m) => m.position), model_matrix: ctx.modelMatrix(),
      });
      if (my !== seq) return;
      overlay.setHidden(new Set(items.filter((_, k) => res.hidden[k]).map((m) => m.key)));
    } catch (exc) {
      if (my !== seq) return;
      overlay.setHidden(new Set()); // no answer: every label drawn as it is
    }
    occ.checks++;
    occ.checkedPose = at; // tests wait for the check of the pose they set
  }

  let pose = "";
  viewer.scene.postRender.addEventListener(() => {
    const key = poseKey();
    if (key === pose) return;
    pose = key;
    later();
  });
  overlay.onMarkersChanged(later);
  occ.check = check;
  occ.poseKey = poseKey;
  window.gsgeo.occlusion = occ;
  return occ;
}
