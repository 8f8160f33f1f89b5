// The registry of measuring tools. main.js sends every click, key and panel button to the
// active tool, whose id is state.mode; a new tool is one module and one line in TOOLS.
// The interface is described in docs/architecture.md ("Web client").

import building from "./building.js";
import idle from "./idle.js";
import line from "./line.js";
import measure from "./measure.js";
import polygon from "./polygon.js";

/** Every tool; the first is the default (selection) tool. Toolbar buttons follow this order. */
export const TOOLS = [
  idle,
  measure,
  line,
  polygon,
  building,
];

export const DEFAULT_TOOL = TOOLS[0];

export function toolById(id) {
  return TOOLS.find((t) => t.id === id) || null;
}

/** The tool started by key `key` (a KeyboardEvent.key, either case), or null. */
export function toolByShortcut(key) {
  if (typeof key !== "string" || key.length !== 1) return null;
  const k = key.toUpperCase();
  return TOOLS.find((t) => t.shortcut && t.shortcut.toUpperCase() === k) || null;
}

/** The active tool (state.mode holds its id). */
export function activeTool(state) {
  return toolById(state.mode) || DEFAULT_TOOL;
}

/** The tool handling a click or pick: the active one, or the default when it has no handler. */
export function handlerOf(state, method) {
  const tool = activeTool(state);
  return typeof tool[method] === "function" ? tool : DEFAULT_TOOL;
}

/** The toolbar buttons (id btn-<tool id>) show which tool is active. */
function markButtons(state) {
  for (const t of TOOLS) {
    const b = document.getElementById(`btn-${t.id}`);
    if (b) b.classList.toggle("active", t.id === state.mode);
  }
}

/** Start tool `id` (with `arg`, e.g. the point to reopen). A tool that needs a project refuses
 *  without one; the active tool is asked to let go first: `leave(ctx, next)` returns whether
 *  it did (without `leave` it is cancelled). Returns whether `id` became active. */
export function activate(ctx, id, arg) {
  const tool = toolById(id);
  if (!tool) throw new Error(`no tool '${id}'`);
  const { state } = ctx;
  if (tool.needsProject && !state.project) { ctx.message("Open a project first.", true); return false; }
  const current = activeTool(state);
  if (current !== DEFAULT_TOOL) {
    if (current.leave) {
      if (!current.leave(ctx, tool)) return false;
    } else {
      current.cancel(ctx);
    }
  }
  state.mode = tool.id;
  markButtons(state);
  tool.start(ctx, arg);
  if (ctx.modeChanged) ctx.modeChanged();
  ctx.updateStatus();
  return true;
}

/** The active tool is done (stored or cancelled): back to the default tool. */
export function release(ctx) {
  ctx.state.mode = DEFAULT_TOOL.id;
  markButtons(ctx.state);
  if (ctx.modeChanged) ctx.modeChanged();
  ctx.updateStatus();
}
