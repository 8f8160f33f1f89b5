// A still of the operator's view: while auto-aim draws its views (each a frame at another
// camera, of the splats reaching a crop), the operator keeps seeing the scene as it was, with
// the measuring overlay on it, and no frame of every splat is needed to bring it back.
//
// The still is a copy of the last frame drawn in full at the present camera (the viewer keeps
// its drawing buffer: preserveDrawingBuffer), shown over the scene's canvas and under the
// overlay. While it shows, the splats are held (render.js's holdSplats: drawn only in the
// frames asked by part) and the globe and sky are hidden, so any frame Cesium draws meanwhile
// costs next to nothing. It goes as soon as it is no longer the view: the camera moved (when
// no auto-aim keeps it), the canvas was resized, or the scene or its georeference changed.

import { holdSplats, sortPending, splatsHeld, splatsHoldable } from "./render.js";
import { sameView, viewOf } from "./overlay.js";

/** How long (ms) the splats may wait for the globe's tiles after the still goes. */
const GLOBE_WAIT_MS = 5000;
/** Splats from which a new view's splats wait for the globe in a software renderer: below, a
 *  frame of every splat costs about what the wait does (the 12 880-splat box scene of the
 *  tests: a tenth of a second), above it costs seconds (the demo's 341 816: 3-7 s at 1280 x
 *  720 in SwiftShader on two cores). */
const GLOBE_WAIT_SPLATS = 100000;

let hiddenBy = 0;
let shownAgain = null;

/** Hide the globe, the sky, the sun and the moon of `scene` (they would cover the feature or
 *  cost time: the sky's atmosphere alone is ~0.6 s of a frame in a software renderer); returns
 *  the function that shows them again. Nested calls share one hiding: the last one shows them
 *  (so nothing changes between auto-aim's views, which would ask for a frame). */
export function hideScenery(scene) {
  if (hiddenBy++ === 0) {
    const items = [scene.globe, scene.skyAtmosphere, scene.skyBox, scene.sun, scene.moon]
      .filter((x) => x && typeof x.show === "boolean");
    const shown = items.map((x) => x.show);
    for (const x of items) x.show = false;
    shownAgain = () => items.forEach((x, i) => { x.show = shown[i]; });
  }
  let done = false;
  return () => {
    if (done) return;
    done = true;
    if (--hiddenBy === 0 && shownAgain) { shownAgain(); shownAgain = null; }
  };
}

export class Still {
  /** `tileset()` is the tileset shown now; `renderer` the page's RenderOnDemand; the still's
   *  canvas goes into `container` before `before`. */
  constructor(viewer, renderer, tileset, container, before = null) {
    this.viewer = viewer;
    this.renderer = renderer;
    this.tileset = tileset;
    this.canvas = document.createElement("canvas");
    this.canvas.className = "gsgeo-still";
    this.canvas.hidden = true;
    container.insertBefore(this.canvas, before);
    this.view = null; // the view shown while the still is up (viewOf), else null
    this.keepers = 0; // how many keep() hold it up whatever the camera does
    this.lastFull = null; // the view of the last frame that drew the scene in full
    this.key = null; // the scene and its model matrix when it was taken
    this.hold = null;
    this.showScenery = null;
    const scene = viewer.scene;
    scene.preRender.addEventListener(() => {
      // (a frame while the still is up, or one drawn by part, is no longer the full scene)
      this.drawingFull = !this.view && !this.keepers && !hiddenBy && !splatsHeld(this.tileset())
        && this.renderer.settled();
    });
    scene.postRender.addEventListener(() => {
      this.lastFull = this.drawingFull ? viewOf(viewer) : null;
      const globe = scene.globe;
      this.globeCalm = !globe || !globe.show || globe.tilesLoaded ? this.globeCalm + 1 : 0;
      if (this.renderer.framesOfAll !== this.framesOfAllSeen) {
        this.framesOfAllSeen = this.renderer.framesOfAll;
        this.drawnAt = viewOf(viewer);
      }
    });
    this.framesOfAllSeen = 0;
    this.drawnAt = null; // the view of the last frame that drew every splat
    this.globeCalm = 0; // frames in a row that found the globe's tiles all loaded
    // every animation tick, drawn or not: the still goes when it is no longer the view
    scene.postUpdate.addEventListener(() => {
      if (this.view && !this.keepers && !this.valid()) this.drop();
      else if (this.releasing) this.release(false);
      else { this.waitForGlobe(); this.completeView(); }
    });
    this.completedAt = null; // the view for which completeView last asked a frame
    this.software = false; // set by the page: a software renderer (render.js's isSoftwareRenderer)
    this.releasing = null; // {hold, since}: the splats given back once the globe is drawn
    this.heldAt = null; // the view for which the splats last waited for the globe
    renderer.waitFor(() => this.releasing !== null);
  }

  /** In a software renderer, a new view of a large scene (GLOBE_WAIT_SPLATS; the camera
   *  moved, the page opened): its splats wait until the globe has loaded its tiles for it, as
   *  after a still (release: two frames in a row with the tiles loaded, at most GLOBE_WAIT_MS),
   *  once per view and never for a view already drawn with every splat (they would vanish
   *  from it). Each tile loaded asks Cesium for a frame, and each frame of every splat costs
   *  seconds there: a camera move took 4 to 9 such frames (25-40 s for the demo at
   *  1280 x 720), and now takes the globe's frames (next to nothing) and one of the splats.
   *  On a GPU the wait would make the splats blink: none there. */
  waitForGlobe() {
    if (!this.software || this.view || this.keepers || hiddenBy) return;
    const globe = this.viewer.scene.globe;
    if (!globe || !globe.show) return;
    const t = this.tileset();
    // (CesiumJS 1.145's private splat count, as render.js reads it)
    if (!t || !t.gaussianSplatPrimitive || !(t.gaussianSplatPrimitive._numSplats >= GLOBE_WAIT_SPLATS)) return;
    const now = viewOf(this.viewer);
    if (!now || sameView(this.heldAt, now) || sameView(this.drawnAt, now)) return;
    // (nor while a sort for the view is under way: held, its result would wait, and Cesium
    // would build it in the middle of the frame after the release, a frame without splats)
    if (splatsHeld(t) || !splatsHoldable(t) || sortPending(t)) return;
    this.heldAt = now;
    this.releasing = { hold: holdSplats(t), since: performance.now() };
    this.globeCalm = 0;
    this.viewer.scene.requestRender();
  }

  /** Once the view has settled, when its last frame was not one of the whole scene (drawn
   *  while a sort was committed, say), ask for one frame more, once per view: so the still
   *  can be taken when the operator clicks (ready()), instead of a frame of every splat being
   *  drawn after the click's reference is read. */
  completeView() {
    if (this.view || this.keepers || hiddenBy) return;
    const now = viewOf(this.viewer);
    if (!now || sameView(this.lastFull, now) || sameView(this.completedAt, now)) return;
    if (!this.renderer.settled() || splatsHeld(this.tileset())) return;
    this.completedAt = now;
    this.viewer.scene.requestRender();
  }

  /** Whether a still of the view could be taken now (take()): its last frame drew the whole
   *  scene, settled, at the present camera. */
  ready() {
    const now = viewOf(this.viewer);
    return !!now && !this.releasing && sameView(this.lastFull, now) && this.renderer.settled();
  }

  /** The view the still shows, or null when there is none (for the overlay). */
  shown() {
    return this.view;
  }

  /** Whether the still is still the view: the camera where it was, the same scene. */
  valid() {
    return sameView(this.view, viewOf(this.viewer)) && this.key === sceneKey(this.tileset());
  }

  /** Put the still up (when it is not): the last frame, when it drew the whole scene, sorted,
   *  at the present camera and the splats can be held; returns whether a still shows. */
  take() {
    if (this.view) return true;
    const t = this.tileset();
    const now = viewOf(this.viewer);
    if (!this.ready() || !splatsHoldable(t)) return false;
    const src = this.viewer.scene.canvas;
    this.canvas.width = src.width;
    this.canvas.height = src.height;
    this.canvas.style.width = `${now.width}px`;
    this.canvas.style.height = `${now.height}px`;
    this.canvas.getContext("2d").drawImage(src, 0, 0);
    this.canvas.hidden = false;
    this.hold = holdSplats(t);
    this.showScenery = hideScenery(this.viewer.scene);
    this.view = now;
    this.key = sceneKey(t);
    return true;
  }

  /** Keep the still up whatever the camera does (auto-aim's views) until the returned function
   *  is called; it goes then if the camera is not back. */
  keep() {
    this.keepers++;
    let done = false;
    return () => {
      if (done) return;
      done = true;
      this.keepers--;
    };
  }

  /** Take the still down: the scene drawn again in full for the present camera. */
  drop() {
    if (!this.view) return;
    this.view = null;
    this.key = null;
    this.canvas.hidden = true;
    if (this.showScenery) this.showScenery();
    this.showScenery = null;
    if (this.hold) {
      // (in a software renderer: the splats are drawn once the globe has loaded its tiles for
      // the new camera, as each tile loaded asks for a frame, and each frame of the splats
      // costs seconds; on a GPU that wait would make them blink)
      this.releasing = { hold: this.hold, since: performance.now() };
      this.globeCalm = 0;
      this.hold = null;
      if (!this.software) this.release();
    }
    this.renderer.request();
  }

  /** Give the splats back to Cesium after drop(): at once, or in a software renderer when the
   *  globe is drawn for the camera (or after GLOBE_WAIT_MS). */
  release(force = true) {
    const r = this.releasing;
    if (!r) return;
    // (the globe may find more tiles to load in the frame after its queues ran empty)
    if (!force && this.globeCalm < 2 && performance.now() - r.since < GLOBE_WAIT_MS) {
      this.viewer.scene.requestRender(); // (frames without the splats: next to nothing)
      return;
    }
    this.releasing = null;
    // (the view's splats have waited for the globe: not again for the same view)
    this.heldAt = viewOf(this.viewer);
    r.hold.release(this.viewer.camera);
    this.renderer.request();
  }
}

const sceneIds = new WeakMap(); // tileset -> a number of its own
let nextSceneId = 1;

/** What the still depends on besides the camera: which tileset, shown or not, and its model
 *  matrix. */
function sceneKey(t) {
  if (!t) return "";
  if (!sceneIds.has(t)) sceneIds.set(t, nextSceneId++);
  return `${sceneIds.get(t)}:${t.show}:${window.Cesium.Matrix4.toArray(t.modelMatrix).join(",")}`;
}
