// The gsgeo JSON API (/api): fetch with the optional token, errors as ApiError with the
// server's message (which names the offending field).

const TOKEN_KEY = "gsgeo-token";

function initialToken() {
  const m = location.hash.match(/token=([^&]+)/);
  if (m) {
    sessionStorage.setItem(TOKEN_KEY, decodeURIComponent(m[1]));
    history.replaceState(null, "", location.pathname + location.search);
  }
  return sessionStorage.getItem(TOKEN_KEY);
}

// Cesium fetches tiles by itself, without our headers: the token goes to /scenes as a
// cookie. Named by port, as cookies are shared by every port of a host; SameSite=Strict
// keeps it out of requests other sites start. The API takes only the header.
function setSceneCookie(value) {
  if (!value) return;
  const port = location.port || (location.protocol === "https:" ? "443" : "80");
  const secure = location.protocol === "https:" ? "; Secure" : "";
  document.cookie = `${TOKEN_KEY}-${port}=${encodeURIComponent(value)}; path=/; SameSite=Strict${secure}`;
}

const token = initialToken();
setSceneCookie(token);

export class ApiError extends Error {
  constructor(status, message, field) {
    super(message);
    this.status = status;
    this.field = field;
  }
}

function headers(extra = {}) {
  return token ? { Authorization: `Bearer ${token}`, ...extra } : extra;
}

async function errorOf(response) {
  let data = null;
  try { data = await response.json(); } catch { /* not JSON */ }
  let msg = (data && (data.message || (typeof data.detail === "string" && data.detail)))
    || `${response.status} ${response.statusText}`;
  if (response.status === 412) msg = `Changed by someone else meanwhile: reload the project (${msg})`;
  return new ApiError(response.status, msg, data && data.field);
}

// Optimistic concurrency: the version of each point, line, polygon and building as this
// client last loaded it, by its API path. A PATCH or DELETE of one sends it as If-Match, so
// a change someone else made meanwhile is refused (412) instead of overwritten.
const versions = new Map();
const COLLECTIONS = ["points", "lines", "polygons", "buildings"];

function remember(method, base, data) {
  if (!data || typeof data !== "object") return;
  for (const key of COLLECTIONS) {
    if (!base.endsWith(`/${key}`) || !Array.isArray(data[key])) continue;
    for (const item of data[key]) {
      if (item && item.id != null && Number.isInteger(item.version)) versions.set(`${base}/${encodeURIComponent(item.id)}`, item.version);
    }
  }
  const parent = method === "POST" ? base : base.slice(0, base.lastIndexOf("/"));
  if (data.id != null && Number.isInteger(data.version) && COLLECTIONS.some((k) => parent.endsWith(`/${k}`))) {
    versions.set(`${parent}/${encodeURIComponent(data.id)}`, data.version);
  }
}

/** JSON request; `body` is sent as JSON, a FormData as multipart. Resolves to the JSON reply. */
export async function api(method, path, body) {
  const init = { method, headers: headers() };
  if (body instanceof FormData) {
    init.body = body;
  } else if (body !== undefined) {
    init.headers = headers({ "Content-Type": "application/json" });
    init.body = JSON.stringify(body);
  }
  const base = path.split("?")[0];
  const version = method === "PATCH" || method === "DELETE" ? versions.get(base) : undefined;
  if (version !== undefined) init.headers = { ...init.headers, "If-Match": `"${version}"` };
  let response;
  try {
    response = await fetch(`/api${path}`, init);
  } catch (exc) {
    throw new ApiError(0, `the gsgeo server cannot be reached (${exc.message})`);
  }
  if (!response.ok) throw await errorOf(response);
  if (version !== undefined) versions.delete(base); // renamed or deleted: known anew below
  if (response.status === 204) return null;
  const data = await response.json();
  remember(method, base, data);
  return data;
}

/** Download a file from the API (with the token) under the server's file name. */
export async function download(path, fallbackName) {
  const response = await fetch(`/api${path}`, { headers: headers() });
  if (!response.ok) throw await errorOf(response);
  const cd = response.headers.get("Content-Disposition") || "";
  const m = cd.match(/filename\*?=(?:UTF-8'')?"?([^";]+)"?/i);
  const name = m ? decodeURIComponent(m[1]) : fallbackName;
  const url = URL.createObjectURL(await response.blob());
  const a = document.createElement("a");
  a.href = url;
  a.download = name;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
  return name;
}
