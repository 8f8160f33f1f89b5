// Scenes whose tiles come from a static host or object store (gsgeo serve --scenes URL): the
// message a failed tile gives the user. A browser hides why a cross-origin request failed;
// Cesium's error then has no status code, which is what a missing CORS header looks like.

/** The text for Cesium's tileFailed event `event` ({url, message}) of scene `name`, whose
 *  tiles come from folder URL `tilesUrl` (null: from the gsgeo server itself). */
export function tileFailureText(name, tilesUrl, event, pageOrigin) {
  const why = (event && event.message) || "";
  if (!tilesUrl) return `A tile of '${name}' failed to load: ${why}`;
  let host = tilesUrl;
  try { host = new URL(tilesUrl).origin; } catch { /* keep the URL as given */ }
  const status = /Status Code: (\d+)/.exec(why);
  if (status) {
    return `A tile of '${name}' failed to load from the static host ${host} (HTTP ${status[1]}): `
      + `${event.url || ""}. Is the scene's folder there (${tilesUrl})?`;
  }
  return `The tiles of '${name}' cannot be read from the static host ${host}: it does not `
    + `answer, or it does not allow this page (CORS). It must send `
    + `'Access-Control-Allow-Origin: ${pageOrigin}' (or *) with the tiles; see the README, `
    + `"Scenes on a static host".`;
}
