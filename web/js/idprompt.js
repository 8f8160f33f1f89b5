// The ID prompt of the measure panel: Enter on a new point asks for its id (prefilled with the
// nearest unmeasured check or control point, else the next free P<n>), Enter again stores it,
// Esc goes back to measuring.

import { $ } from "./format.js";
import { suggestPointId } from "./pointid.js";

export function idPromptOpen() {
  return !$("#id-prompt").hidden;
}

/** Open the prompt for the point being measured (ctx.state.measure), focused, the offered id
 *  selected so that typing replaces it. */
export function openIdPrompt(ctx) {
  const { state } = ctx;
  const input = $("#id-prompt-input");
  input.value = suggestPointId(state.measure.solution, state.checkPointList, state.points);
  $("#id-prompt-error").textContent = "";
  $("#id-prompt").hidden = false;
  input.focus();
  input.select();
  ctx.updateStatus();
}

export function closeIdPrompt() {
  const input = $("#id-prompt-input");
  $("#id-prompt").hidden = true;
  $("#id-prompt-error").textContent = "";
  if (document.activeElement === input) input.blur();
}

/** The id typed in the prompt ("" for the server's next free one). */
export function promptedId() {
  return $("#id-prompt-input").value.trim();
}

/** Say why the id cannot be taken; the prompt stays open for another. */
export function idError(text) {
  $("#id-prompt-error").textContent = text;
  $("#id-prompt-input").focus();
  $("#id-prompt-input").select();
}
