// What auto-aim says when it is done: short, and what to do next. The reasons of the declined
// views are listed in the panel (autoaim.js's autoAimPanel), not in the status line.

const CLICK_ANOTHER = "Click it yourself in another view (V flies to one).";

/** The summary of an auto-aim that ran over `views` views and added `added` rays, `declined`
 *  of the views declined. */
export function autoAimSummary(added, views, declined) {
  if (added === 0) {
    return `Auto-aim found the feature in none of the ${views} views (why: in the panel). ${CLICK_ANOTHER}`;
  }
  const rays = `${added} ray${added === 1 ? "" : "s"}`;
  const why = declined ? `; ${declined} declined (why: in the panel)` : "";
  return `Auto-aim added ${rays} of ${views} views${why}. Review them, then Enter stores the point.`;
}

/** What auto-aim says when it could not start on ray 1 (`reason`: why). */
export function autoAimDeclined(reason) {
  return `Auto-aim declined: ${String(reason).replace(/[.\s]+$/, "")}. ${CLICK_ANOTHER}`;
}

/** Why Enter stored nothing: point `name` has `n` rays, fewer than the 2 a point needs. */
export function tooFewRays(name, n) {
  return `Nothing stored: ${name} has ${n} ray${n === 1 ? "" : "s"} and a point needs 2 or more. ${n ? CLICK_ANOTHER : "Click the feature to add ray 1."}`;
}

/** What the panel says when auto-aim moved ray 1 `px` pixels onto the feature its click was
 *  near (a target's centre, a corner) before looking for it in other views. */
export function snapText(px) {
  return `Ray 1 moved ${px.toFixed(1)} px onto the point feature it was clicked beside.`;
}
