// The shop's web page (docs/web.md).  Plain JavaScript, no build step, no library: it signs
// in (POST /login: a session cookie the script never sees, and a CSRF value it keeps in
// memory), then reads the API (/v1/...) with that cookie and follows the server's event
// stream (/v1/events: the printers and the unfinished jobs, sent when they change).
// Every value from the server goes into the page as text (textContent), never as HTML.
"use strict";

const $ = (id) => document.getElementById(id);
let session = null;            // {name, role, csrf}
let events = null;             // the EventSource
let lastEnded = null;         // the server's mark of ended jobs, as last seen: a change -> history again
const pace = new Map();        // printer -> {key, t0, done0}: the time left from the pace seen
let hasReprint = true;         // the server offers POST /v1/jobs/ID/reprint (else requeue only)

// -- talking to the server -------------------------------------------------------------------
async function api(method, path, body) {
  const headers = {};
  if (method !== "GET") headers["X-Wideprint-CSRF"] = session ? session.csrf : "";
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const r = await fetch(path, {method, headers, credentials: "same-origin", cache: "no-store",
                               body: body === undefined ? undefined : JSON.stringify(body)});
  let data = null;
  try { data = await r.json(); } catch (e) { data = null; }
  if (r.status === 401 && path.startsWith("/v1/")) { signedOut("Signed out: sign in again."); }
  if (!r.ok) {
    const err = new Error((data && data.error) || `${r.status} ${r.statusText}`);
    err.status = r.status;
    throw err;
  }
  return data;
}

function say(text, bad) {
  const m = $("message");
  m.textContent = text || "";
  m.hidden = !text;
  m.classList.toggle("bad", !!bad);
}

// -- signing in and out -----------------------------------------------------------------------
async function start() {
  try {
    const r = await fetch("/session", {credentials: "same-origin", cache: "no-store"});
    if (r.ok) { session = await r.json(); return showApp(); }
  } catch (e) { /* the server is down: the login form says so on submit */ }
  showLogin();
}

function showLogin(text) {
  $("app").hidden = true;
  $("login").hidden = false;
  $("login-error").textContent = text || "";
  $("login-token").value = "";
  $("login-token").focus();
}

async function login(ev) {
  ev.preventDefault();
  $("login-submit").disabled = true;
  $("login-error").textContent = "";
  try {
    const r = await fetch("/login", {method: "POST", credentials: "same-origin",
      headers: {"Content-Type": "application/json"},
      body: JSON.stringify({token: $("login-token").value, name: $("login-name").value})});
    const data = await r.json().catch(() => ({}));
    if (!r.ok) {
      $("login-error").textContent = r.status === 401 ? "Wrong token." : (data.error || r.statusText);
      $("login-token").select();
      return;
    }
    session = data;
    $("login-token").value = "";
    showApp();
  } catch (e) {
    $("login-error").textContent = "The print server does not answer.";
  } finally {
    $("login-submit").disabled = false;
  }
}

function signedOut(text) {
  session = null;
  if (events) { events.close(); events = null; }
  showLogin(text);
}

async function logout() {
  try { await api("POST", "/logout"); } catch (e) { /* signed out anyway */ }
  signedOut("");
}

const operator = () => session && session.role === "operator";
const mayAct = (job) => operator() || (job.owner && session && job.owner === session.name);

function showApp() {
  $("login").hidden = true;
  $("app").hidden = false;
  $("who").textContent = `${session.name || "operator"} (${session.role})`;
  for (const el of document.querySelectorAll(".op-only")) el.hidden = !operator();
  refreshAll();
  follow();
}

// -- live: the event stream --------------------------------------------------------------------
function follow() {
  if (events) events.close();
  lastEnded = null;             // whoever calls follow() has just read the history
  events = new EventSource("/v1/events");
  events.onopen = () => live(true);
  events.addEventListener("printers", (e) => { live(true); showPrinters(JSON.parse(e.data)); });
  events.addEventListener("jobs", (e) => { live(true); showQueue(JSON.parse(e.data)); });
  // the mark of ended jobs (docs/server.md "Live state"): a job that came and went between
  // two samples of "jobs" still reaches the history
  events.addEventListener("ended", (e) => {
    live(true);
    const mark = e.data;
    if (lastEnded !== null && mark !== lastEnded) refreshHistory().catch(() => {});
    lastEnded = mark;
  });
  events.onerror = async () => {
    live(false);
    if (events && events.readyState === EventSource.CLOSED) {
      // refused (signed out, server restarted) or gone: ask, then try again
      const r = await fetch("/session", {credentials: "same-origin", cache: "no-store"}).catch(() => null);
      if (r && r.status === 401) return signedOut("Your session ended: sign in again.");
      setTimeout(() => { if (session) follow(); }, 3000);
    }
  };
}

function live(on) {
  $("live").textContent = on ? "live" : "offline";
  $("live").classList.toggle("off", !on);
}

async function refreshAll() {
  try {
    const st = await api("GET", "/v1/status");
    $("server").textContent = `server ${st.server.version} · ${st.server.url || ""}`;
    showPrinters(st.printers || []);
    const q = await api("GET", "/v1/jobs?state=queued,held,printing");
    showQueue(q.jobs);
    await refreshHistory();
  } catch (e) {
    if (e.status !== 401) say(`Cannot read the server: ${e.message}`, true);
  }
}

async function refreshHistory() {
  const h = await api("GET", "/v1/jobs?state=done,failed,cancelled&newest=1&limit=100");
  showHistory(h.jobs);
  // with the price list's costs where the server prices prints (docs/server.md "Prices
  // and costs"), else the plain accounting
  let rep;
  try { rep = await api("GET", "/v1/report?costs=1"); }
  catch (e) { if (e.status !== 400) throw e; rep = await api("GET", "/v1/report"); }
  const all = await api("GET", "/v1/jobs?state=done,failed,cancelled&newest=1&limit=2000");
  showAccounting(rep.prints, all.jobs, rep.prices && rep.prices.currency);
}

// -- pieces ----------------------------------------------------------------------------------
function el(tag, attrs, ...children) {
  const e = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) {
    if (k === "class") e.className = v;
    else if (k.startsWith("on")) e.addEventListener(k.slice(2), v);
    else if (v !== null && v !== undefined && v !== false) e.setAttribute(k, v);
  }
  for (const c of children) {
    if (c === null || c === undefined) continue;
    e.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return e;
}

function bar(fraction) {
  const inner = el("div");
  inner.style.width = `${Math.max(0, Math.min(1, fraction || 0)) * 100}%`;
  return el("div", {class: "bar", role: "progressbar",
                    "aria-valuenow": Math.round((fraction || 0) * 100)}, inner);
}

function duration(s) {
  if (s === null || s === undefined || !isFinite(s)) return "";
  s = Math.round(s);
  const h = Math.floor(s / 3600), m = Math.floor((s % 3600) / 60), sec = s % 60;
  return h ? `${h} h ${String(m).padStart(2, "0")} min` : m ? `${m} min ${String(sec).padStart(2, "0")} s` : `${sec} s`;
}

function when(epoch) {
  if (!epoch) return "";
  const d = new Date(epoch * 1000);
  return d.toLocaleString(undefined, {month: "short", day: "numeric", hour: "2-digit",
                                      minute: "2-digit", hourCycle: "h23"});
}

const num = (v, digits) => (v === null || v === undefined || !isFinite(v)) ? "" :
  Number(v).toLocaleString(undefined, {minimumFractionDigits: digits, maximumFractionDigits: digits});

async function act(what, path, body, confirmText) {
  if (confirmText && !window.confirm(confirmText)) return;
  try {
    await api("POST", path, body);
    say("");
  } catch (e) {
    if (e.status !== 401) say(`${what}: ${e.message}`, true);
  }
  refreshAll();
}

// -- printers --------------------------------------------------------------------------------
function timeLeft(p) {
  // the GUI's rule (app/gui/printers_panel.py _time_left): the pace seen since this copy
  // was first seen here; nothing until 2 strokes and 2 s
  const cur = p.current;
  if (!cur || !cur.strokes_total) { pace.delete(p.name); return null; }
  const key = `${cur.id}/${cur.copy}`, now = performance.now() / 1000;
  const done = cur.strokes_printed || 0, total = cur.strokes_total;
  const seen = pace.get(p.name);
  if (!seen || seen.key !== key || done < seen.done0) {
    pace.set(p.name, {key, t0: now, done0: done});
    return null;
  }
  if (done - seen.done0 < 2 || now - seen.t0 < 2) return null;
  const perStroke = (now - seen.t0) / (done - seen.done0);
  const after = Math.max(0, (cur.copies || 1) - (cur.copy || 1));
  return perStroke * ((total - done) + after * total);
}

function rollText(p) {
  const r = p.roll;
  const width = (r && r.width_mm) || p.paper_mm;
  let text = width ? `${num(width, 0)} mm paper` : "paper width not measured";
  if (r && r.media) text = `${r.media} · ${text}`;
  if (r && r.remaining_mm !== null && r.remaining_mm !== undefined) text += ` · ${num(r.remaining_mm / 1000, 1)} m left`;
  else if (r) text += " · length unknown";
  return text;
}

function showPrinters(printers) {
  const box = $("printers");
  box.replaceChildren();
  let allPaused = printers.length > 0;
  for (const p of printers) {
    const cur = p.current;
    const state = p.fault ? "fault" : p.paused && p.state !== "printing" ? "paused" : p.state;
    allPaused = allPaused && p.paused;
    const card = el("div", {class: "card" + (p.fault ? " fault" : ""), "data-printer": p.name},
      el("div", {class: "top"}, el("span", {class: "name"}, p.name),
         el("span", {class: `state ${state}`}, state), p.paused && p.state === "printing" ? el("span", {class: "muted"}, "pausing") : null,
         el("span", {class: "grow"}), el("span", {class: "muted small"}, p.device || "")),
      el("div", {class: "muted small roll"}, rollText(p)));
    if (cur) {
      const done = cur.strokes_printed || 0, total = cur.strokes_total || 0;
      const left = timeLeft(p);
      card.append(el("div", {class: "job"}, cur.id ? `#${cur.id} ` : "", cur.name || "",
                     el("span", {class: "muted"}, ` · copy ${cur.copy || 1} of ${cur.copies || 1} · ${cur.state || ""}`)));
      card.append(bar(total ? done / total : 0));
      card.append(el("div", {class: "muted small progress"},
                     total ? `stroke ${done} of ${total}` : (cur.state || ""),
                     left !== null ? ` · ${duration(left)} left` : ""));
    } else {
      card.append(el("div", {class: "muted job"}, p.paused ? `paused: ${p.reason || ""}` : "no job"));
    }
    if (p.fault) card.append(el("div", {class: "fault-text"}, `Fault: ${p.fault}`));
    else if (p.error) card.append(el("div", {class: "fault-text"}, p.error));
    // warnings: nothing stops (docs/server.md "Rolls: the warning")
    for (const w of p.warnings || []) card.append(el("div", {class: "warning-text"}, `Warning: ${w.message}`));
    if (operator()) {
      const acts = el("div", {class: "actions"});
      if (p.paused) acts.append(el("button", {onclick: () => act("resume", `/v1/printers/${encodeURIComponent(p.name)}/resume`)}, "Resume"));
      else acts.append(el("button", {onclick: () => act("pause", `/v1/printers/${encodeURIComponent(p.name)}/pause`)}, "Pause"));
      card.append(acts);
    }
    box.append(card);
  }
  $("queue-toggle").textContent = allPaused ? "Resume queue" : "Pause queue";
  $("queue-toggle").dataset.paused = allPaused ? "1" : "0";
  $("queue-state").textContent = allPaused ? "queue paused" : "";
}

// -- the queue and the history ---------------------------------------------------------------
function thumb(job) {
  return el("td", {class: "thumb"},
            el("img", {src: `/v1/jobs/${job.id}/preview.png`, alt: "", loading: "lazy",
                       onerror: (e) => { e.target.style.visibility = "hidden"; }}));
}

function jobButtons(job) {
  const td = el("td", {class: "acts"});
  if (!mayAct(job)) return td;
  const path = (what) => `/v1/jobs/${job.id}/${what}`;
  const name = job.display_name || job.name;
  const b = (label, what, cls, confirmText) =>
    td.append(el("button", {class: cls || "", "data-action": what,
                            onclick: () => act(`${label} #${job.id}`, path(what), undefined, confirmText)}, label));
  if (job.state === "queued") b("Hold", "hold");
  if (job.state === "held") b("Release", "release", "primary");
  if (["queued", "held"].includes(job.state)) b("Cancel", "cancel", "danger");
  if (job.state === "printing") b("Cancel", "cancel", "danger", `Job ${job.id} (${name}) is printing. Stop it now?`);
  if (["failed", "cancelled"].includes(job.state)) b("Print again", "requeue");
  if (job.state === "done" && hasReprint) {
    td.append(el("button", {"data-action": "reprint", onclick: async () => {
      try { await api("POST", path("reprint"), {}); say(""); }
      catch (e) {
        if (e.status === 404) { hasReprint = false; say("This server cannot reprint a done job (its file is not archived): submit the file again.", true); }
        else if (e.status !== 401) say(`Reprint #${job.id}: ${e.message}`, true);
      }
      refreshAll();
    }}, "Reprint"));
  }
  return td;
}

function showQueue(jobs) {
  const body = $("queue").tBodies[0];
  body.replaceChildren();
  const order = {printing: 0, queued: 1, held: 2};
  jobs.sort((a, b) => (order[a.state] - order[b.state]) || ((a.position || 0) - (b.position || 0)) || (a.id - b.id));
  for (const j of jobs) {
    const total = j.strokes_total || 0;
    body.append(el("tr", {"data-job": j.id, "data-state": j.state},
      thumb(j), el("td", {class: "num"}, j.id),
      el("td", {class: "name", title: j.display_name || j.name}, j.display_name || j.name),
      el("td", {}, j.owner || j.client || ""),
      el("td", {}, el("span", {class: `state ${j.state}`}, j.state),
         j.message ? el("div", {class: "muted small"}, j.message) : null),
      el("td", {class: "num"}, `${j.copies_done || 0}/${j.copies}`),
      el("td", {}, j.printed_on || j.printer || "any"),
      el("td", {}, j.state === "printing" ? bar(total ? (j.strokes_done || 0) / total : 0) : null,
         j.state === "printing" && total ? `${j.strokes_done || 0}/${total}` : j.position ? `#${j.position} in line` : ""),
      jobButtons(j)));
  }
  $("queue-empty").hidden = jobs.length > 0;
  $("queue-count").textContent = jobs.length ? `(${jobs.length})` : "";
}

function showHistory(jobs) {
  const body = $("history").tBodies[0];
  body.replaceChildren();
  for (const j of jobs) {
    body.append(el("tr", {"data-job": j.id, "data-state": j.state},
      thumb(j), el("td", {class: "num"}, j.id),
      el("td", {class: "name", title: j.message || j.display_name || j.name}, j.display_name || j.name),
      el("td", {}, j.owner || j.client || ""),
      el("td", {}, el("span", {class: `state ${j.state}`}, j.state)),
      el("td", {}, when(j.finished)),
      el("td", {}, j.printed_on || ""),
      jobButtons(j)));
  }
  $("history-empty").hidden = jobs.length > 0;
}

// -- accounting: per day and per customer ----------------------------------------------------
function cost(row) {
  // the price list's cost of a print row, when the server sends one (docs/server.md)
  for (const k of ["cost", "cost_total", "total_cost"]) if (typeof row[k] === "number") return row[k];
  if (row.cost && typeof row.cost.total === "number") return row.cost.total;
  return null;
}

function showAccounting(rows, jobs, currency) {
  for (const th of document.querySelectorAll(".figures th.cost")) th.textContent = currency ? `Cost (${currency})` : "Cost";
  const owner = new Map(jobs.map((j) => [j.id, j.owner || j.client || j.source || ""]));
  const group = (keyOf) => {
    const m = new Map();
    for (const r of rows) {
      const k = keyOf(r);
      const g = m.get(k) || {copies: 0, area: 0, ink: 0, time: 0, cost: 0, priced: false};
      if (r.outcome === "done") g.copies += 1;
      g.area += r.area_m2 || 0;
      g.ink += (r.ink_c_ml || 0) + (r.ink_m_ml || 0) + (r.ink_y_ml || 0) + (r.ink_k_ml || 0);
      g.time += r.duration_s || 0;
      const c = cost(r);
      if (c !== null) { g.cost += c; g.priced = true; }
      m.set(k, g);
    }
    return m;
  };
  const fill = (table, m, sortKeys) => {
    const body = $(table).tBodies[0];
    body.replaceChildren();
    for (const k of sortKeys([...m.keys()])) {
      const g = m.get(k);
      body.append(el("tr", {}, el("td", {}, k || "—"), el("td", {}, g.copies),
                     el("td", {}, num(g.area, g.area < 10 ? 3 : 1)),
                     el("td", {}, num(g.ink, g.ink < 10 ? 2 : 1)), el("td", {}, duration(g.time)),
                     el("td", {}, g.priced ? num(g.cost, 2) : "—")));
    }
  };
  const day = (r) => new Date((r.ended || r.started) * 1000).toISOString().slice(0, 10);
  fill("per-day", group(day), (ks) => ks.sort().reverse().slice(0, 14));
  const byCustomer = group((r) => owner.get(r.job_id) || `job ${r.job_id}`);
  fill("per-customer", byCustomer, (ks) => ks.sort((a, b) => byCustomer.get(b).area - byCustomer.get(a).area).slice(0, 14));
}

// -- wiring -----------------------------------------------------------------------------------
document.addEventListener("DOMContentLoaded", () => {
  $("login-form").addEventListener("submit", login);
  $("logout").addEventListener("click", logout);
  $("queue-toggle").addEventListener("click", () =>
    act("the queue", "/v1/queue", {paused: $("queue-toggle").dataset.paused !== "1"}));
  setInterval(() => { if (session && events && events.readyState === EventSource.OPEN) refreshHistory().catch(() => {}); }, 60000);
  start();
});
