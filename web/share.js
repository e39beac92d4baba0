// The share API from the page (docs/share-format.md): where it is, uploading sealed shares,
// fetching and deleting them, and the shares this browser made (local storage). Packing,
// sealing and opening are the worker's (Rust); this file only moves bytes over HTTP.

const SAVED_KEY = 'egoexo-shares';

// The deployment's settings (config.json beside the page, never cached) and the server's
// limits (/api/config). `share_api` null means the page's own origin.
export async function loadShareConfig() {
  let apiBase = location.origin;
  try {
    const response = await fetch(new URL('config.json', location.href), { cache: 'no-cache' });
    if (response.ok) {
      const config = await response.json();
      if (typeof config.share_api === 'string' && config.share_api) apiBase = config.share_api.replace(/\/+$/, '');
    }
  } catch {
    // No config.json: the API is on this origin.
  }
  let server = null;
  try {
    const response = await fetch(`${apiBase}/api/config`);
    if (response.ok) server = await response.json();
  } catch {
    // No share server (a static host without one): sharing says so when tried.
  }
  return { apiBase, server };
}

// The API's error message of a failed answer.
async function apiMessage(response) {
  try {
    const body = await response.json();
    if (body?.error?.message) return body.error.message;
  } catch {
    // not JSON
  }
  return `HTTP ${response.status} ${response.statusText}`;
}

// Uploads a sealed share; resolves to {id, delete_token, expires_at}.
export async function uploadShare(apiBase, sealed, expiry) {
  let response;
  try {
    response = await fetch(`${apiBase}/api/shares?expires=${encodeURIComponent(expiry)}`, {
      method: 'POST',
      headers: { 'Content-Type': 'application/octet-stream' },
      body: sealed,
    });
  } catch (error) {
    throw new Error(`could not reach the share server at ${apiBase}: ${error.message}`);
  }
  if (response.status !== 201) throw new Error(await apiMessage(response));
  return response.json();
}

// Fetches a sealed share; a missing or expired one throws an Error whose `kind` says which.
export async function fetchShare(apiBase, id) {
  let response;
  try {
    response = await fetch(`${apiBase}/api/shares/${encodeURIComponent(id)}`, { cache: 'no-store' });
  } catch (error) {
    throw Object.assign(new Error(`could not reach the share server at ${apiBase}: ${error.message}`), { kind: 'unreachable' });
  }
  if (response.status === 404) {
    throw Object.assign(new Error('This share does not exist: it was deleted, or the link is incomplete.'), { kind: 'not-found' });
  }
  if (response.status === 410) {
    throw Object.assign(new Error('This share has expired: ask for a new link.'), { kind: 'expired' });
  }
  if (!response.ok) throw Object.assign(new Error(await apiMessage(response)), { kind: 'server' });
  return new Uint8Array(await response.arrayBuffer());
}

// Deletes a share with its delete token; resolves to true, or false when it was already gone.
export async function deleteShare(apiBase, id, token) {
  const response = await fetch(`${apiBase}/api/shares/${encodeURIComponent(id)}`, {
    method: 'DELETE',
    headers: { Authorization: `Bearer ${token}` },
  });
  if (response.status === 204) return true;
  if (response.status === 404 || response.status === 410) return false;
  throw new Error(await apiMessage(response));
}

// The shares this browser made: [{id, name, link, created, expires_at, delete_token, api}].
export function savedShares() {
  try {
    const list = JSON.parse(localStorage.getItem(SAVED_KEY) ?? '[]');
    return Array.isArray(list) ? list.filter((s) => s && typeof s.id === 'string') : [];
  } catch {
    return [];
  }
}

export function rememberShare(entry) {
  const list = savedShares().filter((s) => s.id !== entry.id);
  list.unshift(entry);
  localStorage.setItem(SAVED_KEY, JSON.stringify(list.slice(0, 100)));
}

export function forgetShare(id) {
  localStorage.setItem(SAVED_KEY, JSON.stringify(savedShares().filter((s) => s.id !== id)));
}

// "12.3 MB"
export function megabytes(bytes) {
  return `${(bytes / 1e6).toFixed(1)} MB`;
}
