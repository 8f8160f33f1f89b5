// The server's answers merged into the workplace's lists (points, lines, polygons): a store
// (POST, PATCH) answers with the stored object, a DELETE with nothing, so the lists change in
// place instead of being fetched again. Lists keep the server's order (new objects last).

/** `list` with `item` in place of the entry whose id is `oldId` (item.id unless renamed), or
 *  with `item` appended when there is none. */
export function upsert(list, item, oldId = item.id) {
  const i = list.findIndex((x) => x.id === oldId);
  if (i < 0) return [...list, item];
  return [...list.slice(0, i), item, ...list.slice(i + 1)].filter((x, j) => j === i || x.id !== item.id);
}

/** `list` without the entry whose id is `id`. */
export function without(list, id) {
  return list.filter((x) => x.id !== id);
}

/** Whether a line or polygon of `features` uses one of the point ids `ids`: its measures (and,
 *  after a rename, its point list) are the server's to recompute. */
export function usesAny(features, ids) {
  return features.some((f) => f.points.some((q) => ids.includes(q)));
}
