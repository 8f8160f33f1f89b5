// Render on demand: the scene is drawn only when something changes (Cesium's
// requestRenderMode), not 60 times a second while the operator reads the panels.
// Cesium renders by itself on camera moves; this module keeps frames coming while the
// tileset loads and its Gaussian splats are (re)built, and asks the frames a new camera pose
// needs for the splats' order: CesiumJS 1.145 sorts them in a worker, started by a frame, and
// commits the sort in a later frame, without asking for a frame when it is done.
//
// Every frame draws all the splats (seconds each in a software renderer), so no frame is asked
// that draws nothing new: none while the worker sorts, and a finished sort is committed between
// frames (adoptSort) so that the one frame asked then draws it.

/** Frames rendered after an explicit request's own: none (the measuring graphics are on the
 *  2-D overlay, painted after the frame asked). */
const EXTRA_FRAMES = 0;

/** CesiumJS 1.145's GaussianSplatSortingState (a private enum of GaussianSplatPrimitive). */
const SORT_IDLE = 0;
const SORT_SORTING = 2;
const SORT_SORTED = 3;

/** Whether tileset `t`'s Gaussian splats still need frames: tiles loading, a snapshot being
 *  built, a sort to start or to commit (not while the worker sorts, nor while they are held:
 *  holdSplats). CesiumJS 1.145 (pinned) has no public signal for this: it reads the splat
 *  primitive's state (revisit on a Cesium upgrade). */
export function splatsBusy(t) {
  if (!t || !t.show || splatsHeld(t)) return false;
  if (!t.tilesLoaded) return true;
  const p = t.gaussianSplatPrimitive;
  if (!p) return false;
  if (t.statistics.numberOfPointsSelected > 0 && p._numSplats !== t.statistics.numberOfPointsSelected) return true;
  if (p._pendingSnapshot || p._needsSnapshotRebuild || p._dirty || p._pendingSortPromise) return true;
  // the worker sorts: no frame is of use until it is done (adoptSort then asks one)
  if (p._sorterState === SORT_SORTING && p._sorterPromise) return false;
  if (p._sorterState !== undefined && p._sorterState !== SORT_IDLE) return true;
  // no command yet, or one muted by SplatHold.release until the next sort
  return p._numSplats > 0 && (!p._drawCommand || p._drawCommand.instanceCount === 0);
}

/** The splat draw command a frame about to be drawn will draw in full for tileset `t`, or
 *  null (none, muted, or the splats held). CesiumJS 1.145's primitive update pushes the
 *  command it has and only then builds the next one from a finished sort, so the command of
 *  a frame is the one there before it. */
function fullCommand(t) {
  const p = t && t.show && t.gaussianSplatPrimitive;
  if (!p || holds.has(p) || !p._drawCommand || !(p._drawCommand.instanceCount > 0)) return null;
  return p._drawCommand;
}

/** CesiumJS asks for a frame after the next one whenever a web worker finishes a task (the
 *  scene's listener of TaskProcessor.taskCompletedEvent). When the task is the sort of the
 *  splats, that frame draws every splat once more for nothing: the postUpdate above asks the
 *  frame the sort needs (adoptSort). The scene's listener is replaced by one that leaves out
 *  the completions that come while tileset `tileset()`'s splats are being sorted. CesiumJS
 *  1.145 (pinned): the listener's remover is the scene's private
 *  _removeTaskProcessorListenerCallback (revisit on a Cesium upgrade). */
function dropSortCompletionFrames(scene, tileset) {
  const C = window.Cesium;
  const event = C && C.TaskProcessor && C.TaskProcessor.taskCompletedEvent;
  if (!event || typeof scene._removeTaskProcessorListenerCallback !== "function") return;
  scene._removeTaskProcessorListenerCallback();
  scene._removeTaskProcessorListenerCallback = event.addEventListener(() => {
    const t = tileset();
    const p = t && t.show && t.gaussianSplatPrimitive;
    if (p && p._sorterState === SORT_SORTING) return;
    scene.frameState.afterRender.push(() => { scene.requestRender(); });
  });
}

/** CesiumJS reads the camera's heading and roll on every animation tick while anything listens
 *  to camera.changed, and each read turns the camera's axes into its local east-north-up frame
 *  and back: the direction drifts by ~3e-16 a tick, which the scene's camera check (relative
 *  1e-15) takes for a move every few ticks. After every camera move that made 15-25 more
 *  frames (each of every splat: 22 CPU-seconds for one arrow key on the demo in a software
 *  renderer, against 5 without) until the drift found a fixed point. The only listener is the
 *  Viewer's default data source's entity clustering, and nothing here is an entity: its
 *  listener is removed. CesiumJS 1.145 (pinned): EntityCluster's private _removeEventListener,
 *  the remover its destroy() calls (revisit on a Cesium upgrade). */
function stopHeadingDrift(viewer) {
  const display = viewer.dataSourceDisplay;
  const cluster = display && display.defaultDataSource && display.defaultDataSource.clustering;
  if (cluster && typeof cluster._removeEventListener === "function") {
    cluster._removeEventListener();
    cluster._removeEventListener = undefined;
  }
}

/** Whether a sort of tileset `t`'s splats is under way or waits to be committed. */
export function sortPending(t) {
  const p = t && t.show && t.gaussianSplatPrimitive;
  return !!p && !holds.has(p) && ((p._sorterState !== undefined && p._sorterState !== SORT_IDLE) || !!p._sorterPromise);
}

/** When the worker has finished sorting tileset `t`'s splats, build the draw command of the
 *  new order now, as CesiumJS 1.145 does for a new snapshot's first sort, instead of in the
 *  next frame (which would draw the old order once more, then the new one a frame later);
 *  returns whether it did. The same steps as the primitive's update in its SORTED state. */
function adoptSort(t, scene) {
  const p = t && t.show && t.gaussianSplatPrimitive;
  if (!p || holds.has(p) || p._sorterState !== SORT_SORTED) return false;
  const build = p.constructor && p.constructor.buildGSplatDrawCommand;
  if (typeof build !== "function" || !scene.frameState) return false;
  build(p, scene.frameState);
  p._sorterState = SORT_IDLE;
  p._dirty = false;
  p._sorterPromise = undefined;
  p._activeSort = undefined;
  return true;
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

/** Renderers that draw on the CPU (Chromium's SwiftShader, Mesa's llvmpipe and softpipe,
 *  Windows' Basic Render Driver): there a frame of every splat costs seconds. */
const SOFTWARE_RENDERER = /swiftshader|llvmpipe|softpipe|basic render driver/i;

/** The name of WebGL context `gl`'s renderer, unmasked where the browser tells it ("" when
 *  unknown). */
export function rendererName(gl) {
  if (!gl) return "";
  const info = gl.getExtension("WEBGL_debug_renderer_info");
  return String((info && gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) || gl.getParameter(gl.RENDERER) || "");
}

/** Whether the renderer named `renderer` (rendererName) draws on the CPU. */
export function isSoftwareRenderer(renderer) {
  return SOFTWARE_RENDERER.test(renderer);
}

/** Multisampling for the viewer: the page's `?msaa=` value `param` (null when absent: "keep"
 *  is Cesium's default, 1, 2, 4 or 8 that many samples) and otherwise none (1) on a software
 *  renderer named `renderer`, where 4 samples make the splats' blending cost ~1.5 times as
 *  much for edges a splat scene hardly has. Returns the sample count to set, or null to keep
 *  Cesium's default. */
export function msaaSamplesFor(param, renderer) {
  if (param === "keep") return null;
  if (param !== null && /^[1248]$/.test(param)) return Number(param);
  return SOFTWARE_RENDERER.test(renderer) ? 1 : null;
}

export class RenderOnDemand {
  /** `tileset()` returns the tileset shown now (or null). */
  constructor(viewer, tileset) {
    this.viewer = viewer;
    this.tileset = tileset;
    this.pending = 0;
    this.waits = [];
    this.frames = 0; // frames rendered since the page started (tests count them)
    this.framesOfAll = 0; // those of them that drew every splat (seconds each in software)
    const scene = viewer.scene;
    scene.requestRenderMode = true;
    // nothing in the scene depends on simulation time
    scene.maximumRenderTimeChange = Number.POSITIVE_INFINITY;
    this.moving = false;
    dropSortCompletionFrames(scene, () => this.tileset());
    stopHeadingDrift(viewer);
    let command = null; // the command the frame being drawn draws in full (fullCommand)
    scene.preRender.addEventListener(() => { command = fullCommand(this.tileset()); });
    scene.postRender.addEventListener(() => {
      this.frames++;
      // (not when the splats were held during the frame, nor muted: then it was no frame of
      // every splat, although Cesium may have built a full command meanwhile)
      if (command && command.instanceCount > 0 && !splatsHeld(this.tileset())) this.framesOfAll++;
      command = null;
    });
    viewer.camera.moveStart.addEventListener(() => { this.moving = true; });
    viewer.camera.moveEnd.addEventListener(() => { this.moving = false; });
    // a frame about to be drawn for a new pose (a jump, the end of a flight) starts the sort
    // for it now rather than 3 frames after the last one (Cesium's own pace)
    scene.preRender.addEventListener(() => { askSortFor(this.tileset(), viewer.camera); });
    // runs on every animation tick, rendered or not: ask for the next frame while needed
    scene.postUpdate.addEventListener(() => {
      const t = this.tileset();
      if (adoptSort(t, scene)) {
        scene.requestRender();
      } else if (this.pending > 0) {
        this.pending--;
        scene.requestRender();
      } else if (this.busy()) {
        scene.requestRender();
      } else if (!this.moving && askSortFor(t, viewer.camera)) {
        scene.requestRender();
      }
    });
  }

  /** Whether the tileset still needs frames to show everything for this camera. */
  busy() {
    return splatsBusy(this.tileset());
  }

  /** Whether the view is drawn as it will stay: no frame asked or needed, the splats sorted
   *  for the camera (the operator sees the scene as it is). */
  settled() {
    const t = this.tileset();
    return this.pending === 0 && !this.busy() && !sortPending(t) && !needsSort(t, this.viewer.camera)
      && !this.waits.some((w) => w());
  }

  /** `fn()` tells whether the view waits for something else before it is drawn as it will
   *  stay (still.js: the splats held back until the globe has loaded). */
  waitFor(fn) {
    this.waits.push(fn);
  }

  /** Something drawn changed: render now and `extra` frames more. */
  request(extra = EXTRA_FRAMES) {
    this.pending = Math.max(this.pending, extra);
    this.viewer.scene.requestRender();
  }
}

// ---------------------------------------------------------------------------------------
// Drawing only the splats that reach part of the window (auto-aim's crops)

/** Splats whose centre is this many standard deviations (their largest scale) from a box
 *  may still reach it: Cesium's splat quad reaches 2 sigma (CesiumJS 1.145's shaders). */
const REACH_SIGMAS = 3;
/** Pixels added to each splat's reach (Cesium's 0.3 px² low-pass and rounding). */
const REACH_PX = 2;

const holds = new WeakMap(); // Gaussian splat primitive -> its SplatHold
const radii = new WeakMap(); // a snapshot's scales array -> Float32Array of reach radii (m)

/** Whether the committed splat snapshot of tileset `t` holds every tile of the tileset with
 *  content, so that no camera can select a splat it lacks (one-tile scenes, or all loaded). */
function snapshotHoldsAll(t, p) {
  const set = p._selectedTileSet;
  if (!set || !t.root) return false;
  const stack = [t.root];
  while (stack.length) {
    const tile = stack.pop();
    if (tile.hasRenderableContent && !set.has(tile)) return false;
    for (const c of tile.children) stack.push(c);
  }
  return true;
}

/**
 * While held, the Gaussian splats of a tileset are drawn only when asked, and then only those
 * whose footprint can reach a given window box, in back-to-front order for the camera of
 * that frame. The pixels inside the box are those of a full frame (the splats left out
 * cannot reach it, the order of the rest is the full order restricted to them), at a
 * fraction of the cost: the splats' vertex work is the larger part of a software frame.
 *
 * CesiumJS 1.145 (pinned) has no public way to draw a subset: the hold replaces the splat
 * primitive's per-frame update on that one object (so Cesium's own sorting and rebuilds wait),
 * writes the subset's indexes into its instance buffer and sets the draw command's instance
 * count; release() writes Cesium's own sorted indexes back and restores both. Revisit on a
 * Cesium upgrade (it reads _positions, _scales, _indexes, _drawCommand, _vertexArray).
 */
class SplatHold {
  constructor(t, p) {
    this.t = t;
    this.p = p;
    this.users = 1;
    this.command = p._drawCommand;
    // (a command muted meanwhile, by SplatHold.release or autoaim.js, draws all its indexes)
    this.count = this.command.instanceCount || (p._indexes ? p._indexes.length : p._numSplats);
    this.armed = false;
    this.drawnFrame = -1;
    this.ownUpdate = Object.prototype.hasOwnProperty.call(p, "update") ? p.update : undefined;
    const hold = this;
    p.update = function heldUpdate(frameState) {
      if (!hold.t.show || !hold.armed || !frameState.passes.render) return;
      frameState.commandList.push(hold.command);
      hold.drawnFrame = frameState.frameNumber;
    };
  }

  /** Reach radius (m) of every splat of the snapshot: REACH_SIGMAS x its largest scale. */
  radii() {
    const s = this.p._scales;
    let r = radii.get(s);
    if (!r) {
      const n = this.p._numSplats;
      r = new Float32Array(n);
      for (let i = 0; i < n; i++) {
        r[i] = REACH_SIGMAS * Math.max(s[3 * i], s[3 * i + 1], s[3 * i + 2]);
      }
      radii.set(s, r);
    }
    return r;
  }

  /**
   * Arm the next frame to draw the splats that can reach window box `box` = [x0, y0, w, h]
   * (CSS px) of Cesium camera `camera` (perspective, the one the frame will use) on a window
   * of `width` x `height` CSS px; returns how many splats that is.
   */
  arm(camera, box, width, height) {
    const p = this.p;
    const Cesium = window.Cesium;
    const mv = Cesium.Matrix4.multiply(camera.viewMatrix, p._rootTransform, new Cesium.Matrix4());
    const f = height / (2 * Math.tan(camera.frustum.fovy / 2));
    const cx = width / 2;
    const cy = height / 2;
    const [bx0, by0, bw, bh] = box;
    const bx1 = bx0 + bw;
    const by1 = by0 + bh;
    const pos = p._positions;
    const rad = this.radii();
    const n = p._numSplats;
    const keep = new Uint32Array(n);
    const depth = new Float32Array(n);
    let m = 0;
    for (let i = 0; i < n; i++) {
      const x = pos[3 * i];
      const y = pos[3 * i + 1];
      const z = pos[3 * i + 2];
      // view coordinates: the camera looks along -z
      const vz = mv[2] * x + mv[6] * y + mv[10] * z + mv[14];
      const w = -vz;
      const r = rad[i];
      if (w > r) {
        const vx = mv[0] * x + mv[4] * y + mv[8] * z + mv[12];
        const vy = mv[1] * x + mv[5] * y + mv[9] * z + mv[13];
        const u = cx + (f * vx) / w;
        const v = cy - (f * vy) / w;
        const reach = (f * r) / w + REACH_PX;
        if (u + reach < bx0 || u - reach > bx1 || v + reach < by0 || v - reach > by1) continue;
      } // else: at or behind the camera's plane, left to Cesium's shader as in a full frame
      keep[m] = i;
      depth[m] = vz;
      m++;
    }
    // back to front: the farthest (most negative view z) first, as Cesium's sort orders them
    const order = new Uint32Array(m);
    for (let k = 0; k < m; k++) order[k] = k;
    order.sort((a, b) => depth[a] - depth[b]);
    const out = new Uint32Array(m);
    for (let k = 0; k < m; k++) out[k] = keep[order[k]];
    p._vertexArray.getAttribute(1).vertexBuffer.copyFromArrayView(out);
    this.command.instanceCount = m;
    this.armed = true;
    this.drawnFrame = -1;
    return m;
  }

  /** Nothing of the splats is drawn from the next frame on (until armed again). */
  disarm() {
    this.armed = false;
  }

  /** Give the primitive back to Cesium (its own sorted indexes, count and update), the
   *  viewer's camera `camera` being where it will be drawn next. When Cesium's last sort is
   *  not for that camera, its draw command stays muted (nothing of the splats drawn) until
   *  Cesium has sorted them for it and built the next command, and that sort is asked now:
   *  so no frame draws every splat in a stale order (a full frame costs seconds). */
  release(camera) {
    if (--this.users > 0) return;
    const p = this.p;
    holds.delete(p);
    if (this.ownUpdate) p.update = this.ownUpdate;
    else delete p.update;
    if (p._indexes && p._vertexArray && p._indexes.length <= p._vertexArrayLen) {
      p._vertexArray.getAttribute(1).vertexBuffer.copyFromArrayView(p._indexes);
    }
    const idle = p._sorterState === 0 && !p._sorterPromise; // 0: IDLE
    if (camera && p._drawCommand === this.command && !(idle && sortedForCamera(p, camera))) {
      this.command.instanceCount = 0;
      askSortFor(this.t, camera);
    } else {
      this.command.instanceCount = this.count;
    }
  }
}

/** Whether splat primitive `p`'s last sort was made for Cesium camera `camera`, within
 *  Cesium's own re-sort thresholds (1 m, 0.5 degree). */
function sortedForCamera(p, camera) {
  if (!p._hasLastSteadySortCameraPosition || !p._hasLastSteadySortCameraDirection) return false;
  const C = window.Cesium;
  return C.Cartesian3.distance(camera.positionWC, p._lastSteadySortCameraPosition) < 1.0
    && C.Cartesian3.angleBetween(camera.directionWC, p._lastSteadySortCameraDirection) < 0.0087;
}

/** Whether the splats of tileset `t` were last sorted for another pose than Cesium camera
 *  `camera`'s while no sort or rebuild is under way (askSortFor's condition). */
function needsSort(t, camera) {
  const p = t && t.show && t.gaussianSplatPrimitive;
  if (!p || holds.has(p) || !p._drawCommand || !(p._numSplats > 0) || !p._prevViewMatrix) return false;
  if (p._sorterState !== 0 || p._sorterPromise || p._pendingSnapshot || p._pendingSortPromise) return false;
  return !sortedForCamera(p, camera);
}

/** When the splats of tileset `t` were last sorted for another pose than Cesium camera
 *  `camera`'s and no sort or rebuild is under way, make the next frame sort them for it and
 *  return true. CesiumJS 1.145 re-sorts on a camera change only when its last sort was at
 *  least 3 frames before, and otherwise waits for the next change: a camera that stops within
 *  3 frames of a sort would keep the old order. */
export function askSortFor(t, camera) {
  if (!needsSort(t, camera)) return false;
  const p = t.gaussianSplatPrimitive;
  p._lastSteadySortFrameNumber = -1;
  window.Cesium.Matrix4.clone(window.Cesium.Matrix4.ZERO, p._prevViewMatrix);
  return true;
}

/** Hold the splats of tileset `t` (see SplatHold): the hold, or null when its splats cannot be
 *  drawn by parts now (not a Gaussian splat tileset, a snapshot not yet built or not holding
 *  every tile, a sort of new tiles under way). Nested holds share one; each one is
 *  released. */
export function holdSplats(t) {
  if (!splatsHoldable(t)) return null;
  const p = t.gaussianSplatPrimitive;
  const h = holds.get(p);
  if (h) { h.users++; return h; }
  const hold = new SplatHold(t, p);
  holds.set(p, hold);
  return hold;
}

/** Whether holdSplats(t) would give a hold now (or one is held). */
export function splatsHoldable(t) {
  const p = t && t.gaussianSplatPrimitive;
  if (!p || !t.tilesLoaded) return false;
  if (holds.has(p)) return true;
  if (!p._drawCommand || !p._vertexArray || !p._positions || !p._scales || !p._rootTransform) return false;
  if (p._pendingSnapshot || p._needsSnapshotRebuild || p._dirty) return false;
  const n = p._numSplats;
  if (!(n > 0) || p._positions.length < 3 * n || p._scales.length < 3 * n || p._vertexArrayLen < n) return false;
  return snapshotHoldsAll(t, p);
}

/** Whether tileset `t`'s splats are held (drawn only when asked). */
export function splatsHeld(t) {
  const p = t && t.gaussianSplatPrimitive;
  return !!p && holds.has(p);
}
