// Render on demand: the scene is drawn only when something changes (Cesium's
// requestRenderMode), not 60 times a second while the operator reads the panels.
// Cesium renders by itself on camera moves; this module keeps frames coming while the
// tileset loads and while its Gaussian splats are (re)built and sorted for the camera (CesiumJS
// 1.145 does that over several frames and in a worker, without asking for a frame when it is
// done), and a few frames after the page changes what the overlay or the entities show.


/** Frames rendered after an explicit request: entities (labels, points) may take one or two
 *  frames to appear after they are added. */
const SETTLE_FRAMES = 3;
/** Frames rendered after the camera stops: the splats are sorted again for the new pose once
 *  three frames have passed since the last sort (CesiumJS 1.145); the sort itself then keeps
 *  frames coming (splatsBusy). */
const CAMERA_SETTLE_FRAMES = 6;

/** Whether tileset `t`'s Gaussian splats still need frames: tiles loading, a snapshot being
 *  built or a sort under way. CesiumJS 1.145 (pinned) has no
 *  public signal for this: it reads the splat primitive's state (revisit on a Cesium upgrade). */
export function splatsBusy(t) {
  if (!t || !t.show) return false;
  if (!t.tilesLoaded) return true;
  const p = t.gaussianSplatPrimitive;
  if (!p) return false;
  if (t.statistics.numberOfPointsSelected > 0 && p._numSplats !== t.statistics.numberOfPointsSelected) return true;
  if (p._pendingSnapshot || p._needsSnapshotRebuild || p._dirty || p._pendingSortPromise || p._sorterPromise) return true;
  if (p._sorterState !== undefined && p._sorterState !== 0) return true; // 0: IDLE
  return !p._drawCommand && p._numSplats > 0;
}

/** Whether tileset `t` shows its scene: every tile loaded and, for Gaussian splats, every
 *  selected splat in the drawn snapshot (the same private state as splatsBusy). */
export function splatsShown(t) {
  if (!t || !t.tilesLoaded) return false;
  const p = t.gaussianSplatPrimitive;
  if (!p) return true;
  const n = t.statistics.numberOfPointsSelected;
  return n > 0 && p._numSplats === n && !!p._drawCommand;
}

export class RenderOnDemand {
  /** `tileset()` returns the tileset shown now (or null). */
  constructor(viewer, tileset) {
    this.viewer = viewer;
    this.tileset = tileset;
    this.pending = 0;
    this.frames = 0; // frames rendered since the page started (tests count them)
    const scene = viewer.scene;
    scene.requestRenderMode = true;
    // nothing in the scene depends on simulation time
    scene.maximumRenderTimeChange = Number.POSITIVE_INFINITY;
    scene.postRender.addEventListener(() => { this.frames++; });
    viewer.camera.moveEnd.addEventListener(() => this.request(CAMERA_SETTLE_FRAMES));
    // runs on every animation tick, rendered or not: ask for the next frame while needed
    scene.postUpdate.addEventListener(() => {
      if (this.pending > 0) {
        this.pending--;
        scene.requestRender();
      } else if (this.busy()) {
        scene.requestRender();
      }
    });
  }

  /** Whether the tileset still needs frames to show everything for this camera. */
  busy() {
    return splatsBusy(this.tileset());
  }

  /** Something drawn changed: render now and `frames` frames more. */
  request(frames = SETTLE_FRAMES) {
    this.pending = Math.max(this.pending, frames);
    this.viewer.scene.requestRender();
  }
}
