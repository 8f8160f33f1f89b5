// The default tool, active whenever no other is: a click on a point marker selects the point,
// a row of the points list selects it and flies there. Tools that leave out click or pick
// get this behaviour (tools/index.js).

const idle = {
  id: "idle",

  start() {},

  click(ctx, event) {
    const id = ctx.nearestPoint(event.position, 14);
    if (id) ctx.selectPoint(id, false);
  },

  /** A row of the points list was clicked. */
  pick(ctx, id) {
    ctx.selectPoint(id, true);
  },

  status(ctx) {
    const { state } = ctx;
    let text;
    if (!state.sceneName) {
      text = "No scene loaded. Make one with `gsgeo tiles INPUT.ply -o DATA/scenes/NAME --origin LAT,LON,H` and pick it above.";
    } else if (!state.project) {
      text = "Create or open a project (top bar) to store points. M measures a point, ? shows help.";
    } else {
      text = "M (or Measure point) starts a point; a click on a point marker selects it. L line, P polygon, B building, G georeference, ? help. Drag moves, right drag orbits, wheel zooms, Home goes back.";
    }
    return { text, className: "" };
  },
};

export default idle;
