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
  const msg = (data && (data.message || (typeof data.detail === "string" && data.detail)))
    || `${response.status} ${response.statusText}`;
  return new ApiError(response.status, msg, data && data.field);
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
  let response;
  try {
    response = await fetch(`/api${path}`, init);
  } catch (exc) {
    throw new ApiError(0, `the gsgeo server cannot be reached (${exc.message})`);
  }
  if (!response.ok) throw await errorOf(response);
  if (response.status === 204) return null;
  return response.json();
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
