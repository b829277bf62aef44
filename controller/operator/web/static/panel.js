/* The operator's panel: one WebSocket (JSON-RPC 2.0 calls, the pushed status, log, job and
   queue events), uploads over HTTP. Every action goes through the API, which goes through
   cncd's control socket: the daemon refuses here what it refuses to cncctl. */
"use strict";

const $ = (id) => document.getElementById(id);
let ws = null, nextId = 1, token = sessionStorage.getItem("phcnc-token") || "";
const pending = new Map();
const preview = new PathPreview($("preview"));
let previewName = null, status = {}, jogTimer = null, jogHeld = null, retryMs = 500;

function say(text, bad) { const m = $("message"); m.textContent = text || ""; m.style.color = bad ? "#ff8a80" : ""; }

function connect() {
  const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws";
  ws = new WebSocket(url);
  ws.onopen = () => {
    retryMs = 500;
    // always first: with a token configured the server takes nothing else first
    ws.send(JSON.stringify({jsonrpc: "2.0", id: 0, method: "auth", params: {token}}));
    $("conn").textContent = "connected";
    refreshLibrary(); refreshQueue();
    rpc("log", {lines: 50}).then((r) => { $("log").innerHTML = ""; r.events.forEach(addLog); }).catch(() => {});
  };
  ws.onmessage = (e) => onMessage(JSON.parse(e.data));
  ws.onclose = (e) => {
    $("conn").textContent = "disconnected";
    // what the page shows is no longer live: said plainly, never left as RUNNING or IDLE
    $("state").textContent = "OFFLINE"; $("state").className = "state OFFLINE";
    stopJogLocally();
    for (const [, p] of pending) p.reject(new Error("connection closed"));
    pending.clear();
    if (e.code === 4401 || e.code === 1008) { askToken(); return; }
    setTimeout(connect, retryMs); retryMs = Math.min(retryMs * 2, 5000);
  };
}

function askToken() {
  const d = $("token-dialog");
  d.showModal();
  d.onclose = () => { token = $("token-input").value.trim(); sessionStorage.setItem("phcnc-token", token); connect(); };
}

function rpc(method, params) {
  return new Promise((resolve, reject) => {
    if (!ws || ws.readyState !== WebSocket.OPEN) { reject(new Error("not connected")); return; }
    const id = nextId++;
    pending.set(id, {resolve, reject});
    ws.send(JSON.stringify({jsonrpc: "2.0", id, method, params: params || {}}));
  });
}

function act(method, params) {
  return rpc(method, params).then((r) => { say(""); return r; })
    .catch((e) => { say(method + ": " + e.message, true); throw e; });
}

function onMessage(m) {
  if (m.id !== undefined && pending.has(m.id)) {
    const p = pending.get(m.id); pending.delete(m.id);
    m.error ? p.reject(new Error(m.error.message)) : p.resolve(m.result);
    return;
  }
  if (m.method === "status") showStatus(m.params);
  else if (m.method === "log") addLog(m.params);
  else if (m.method === "job") showJob(m.params);
  else if (m.method === "queue") showQueue(m.params.queue);
}

const fmt = (v) => (v === undefined || v === null) ? "-" : v.toFixed(3);

function showStatus(s) {
  if (status.seq === undefined) performance.mark("first-status");  // the panel's load time
  status = s;
  const st = $("state"); st.textContent = s.state; st.className = "state " + s.state;
  $("alarm").textContent = s.fault || (s.estop_input ? "e-stop input open" : "");
  $("estop").classList.toggle("latched", s.state === "ESTOP");
  const m = s.position_mm || {}, w = s.work_position_mm || {};
  for (const a of ["x", "y", "z"]) { $("dro-m" + a).textContent = fmt(m[a]); $("dro-w" + a).textContent = fmt(w[a]); }
  $("dro-mz").parentElement.hidden = m.z === undefined;  // an X-Y table has no Z row
  for (const b of document.querySelectorAll(".jog[data-axis='z']")) b.hidden = m.z === undefined;
  $("feed").textContent = ((s.feed_mm_s || 0) * 60).toFixed(0);
  $("line").textContent = s.line ?? "-";
  $("ferror").textContent = (s.ferror_um || 0).toFixed(1);
  $("program").textContent = s.program || "-";
  if (document.activeElement !== $("override")) {
    $("override").value = s.feed_override_pct; $("override-value").textContent = s.feed_override_pct;
  }
  if (s.offsets && document.activeElement !== $("offset-system")) $("offset-system").value = s.offsets.active;
  if (w.x !== undefined) {
    const running = ["RUNNING", "HELD", "PAUSED"].includes(s.state) && s.program === previewName;
    preview.setTool(w.x, w.y, s.line, running);
  }
}

function addLog(e) {
  const li = document.createElement("li");
  const when = typeof e.time === "number" ? new Date(e.time * 1000).toLocaleTimeString() : (e.time || "");
  li.className = "p" + e.priority; li.textContent = when + " " + e.message;
  const log = $("log"); log.prepend(li);
  while (log.children.length > 200) log.lastChild.remove();
}

function showJob(j) {
  if (j.event && j.event.event === "rejected") say(j.event.message, true);
  if (j.final) {
    say(j.name + ": " + j.state + (j.message ? ": " + j.message : ""), j.state !== "done");
    if (j.name === "MDI") markMdi(j);
  }
}

/* -- buttons ------------------------------------------------------------------------------ */
$("estop").onclick = () => act("estop");
$("hold").onclick = () => act("hold");
$("resume").onclick = () => act("resume");
$("abort").onclick = () => act("abort");
$("reset").onclick = () => act("reset");
$("home").onclick = () => act("home");
$("override").oninput = () => { $("override-value").textContent = $("override").value; };
$("override").onchange = () => act("feed", {percent: Number($("override").value)});
$("offset-select").onclick = () => act("offset", {action: "select", system: $("offset-system").value});
$("offset-here").onclick = () => act("offset", {action: "set", system: $("offset-system").value, here: true});
$("offset-g92").onclick = () => act("offset", {action: "clear-g92"});

/* -- jog: a step, or continuous while pressed (renewed every 0.2 s; the server stops it when
   the renewals stop, the button is released, the page is hidden or closed) ----------------- */
function jogFeed() { return Number($("jog-feed").value) || 600; }

function stopJogLocally() {
  if (jogTimer) clearInterval(jogTimer);
  jogTimer = null;
  if (jogHeld) jogHeld.classList.remove("held");
  jogHeld = null;
}

function jogStop() {
  if (!jogHeld) return;
  stopJogLocally();
  rpc("jog_stop").catch(() => {});
}

for (const b of document.querySelectorAll(".jog")) {
  b.addEventListener("pointerdown", (e) => {
    e.preventDefault();
    const axis = b.dataset.axis, dir = Number(b.dataset.dir), step = $("jog-step").value;
    if (step !== "cont") { act("jog", {axis, distance_mm: dir * Number(step), feed_mm_min: jogFeed()}); return; }
    b.setPointerCapture(e.pointerId);
    jogHeld = b; b.classList.add("held");
    act("jog", {axis, direction: dir, feed_mm_min: jogFeed()}).catch(stopJogLocally);
    jogTimer = setInterval(() => rpc("jog_renew").catch(() => {}), 200);
  });
  for (const ev of ["pointerup", "pointercancel", "lostpointercapture"]) b.addEventListener(ev, jogStop);
}
document.addEventListener("visibilitychange", () => { if (document.hidden) jogStop(); });
window.addEventListener("blur", jogStop);
window.addEventListener("pagehide", jogStop);

/* -- MDI ---------------------------------------------------------------------------------- */
$("mdi-form").onsubmit = (e) => {
  e.preventDefault();
  const text = $("mdi-text").value.trim();
  if (!text) return;
  const li = document.createElement("li"); li.textContent = text + "  (sent)";
  $("mdi-history").prepend(li);
  act("mdi", {text}).then(() => { $("mdi-text").value = ""; li.dataset.pending = "1"; })
    .catch((err) => { li.textContent = text + "  (refused: " + err.message + ")"; });
};

function markMdi(j) {
  const li = document.querySelector("#mdi-history li[data-pending='1']");
  if (!li) return;
  delete li.dataset.pending;
  li.textContent = li.textContent.replace("(sent)", "(" + j.state + (j.message ? ": " + j.message : "") + ")");
}

/* -- library, preview, queue -------------------------------------------------------------- */
function refreshLibrary() {
  rpc("programs.list").then((r) => {
    const ul = $("library"); ul.innerHTML = "";
    for (const p of r.programs) {
      const li = document.createElement("li");
      const name = document.createElement("span"); name.textContent = p.name + " (" + p.bytes + " B)";
      li.append(name);
      for (const [label, fn] of [["Preview", showPreview], ["Run", runProgram], ["Queue", queueProgram], ["Delete", deleteProgram]]) {
        const b = document.createElement("button"); b.textContent = label; b.dataset[label.toLowerCase()] = p.name;
        b.onclick = () => fn(p.name); li.append(b);
      }
      ul.append(li);
    }
  }).catch(() => {});
}

function showPreview(name) {
  return act("programs.preview", {name}).then((p) => {
    previewName = name; preview.load(p);
    $("preview-name").textContent = name;
    $("preview-note").textContent = p.points + " points" + (p.truncated ? " (cut short)" : "") + (p.error ? "; " + p.error : "");
  });
}

function runProgram(name) { showPreview(name).finally(() => act("run", {name})); }
function queueProgram(name) { act("queue.add", {name}).then(refreshQueue); }
function deleteProgram(name) { if (confirm("Delete " + name + "?")) act("programs.delete", {name}).then(refreshLibrary); }

$("upload-form").onsubmit = (e) => {
  e.preventDefault();
  const file = $("upload-file").files[0];
  if (!file) { say("choose a file first", true); return; }
  const name = file.name.replace(/[^A-Za-z0-9._-]/g, "_").replace(/^[._-]+/, "").slice(0, 100) || "program.nc";
  const headers = {"Content-Type": "application/octet-stream"};
  if (token) headers.Authorization = "Bearer " + token;
  fetch("/api/programs/" + encodeURIComponent(name), {method: "POST", body: file, headers})
    .then((r) => r.json().then((j) => { if (!r.ok) throw new Error(j.error.message); return j; }))
    .then((j) => { say("uploaded " + j.name); refreshLibrary(); })
    .catch((err) => say("upload: " + err.message, true));
};

function refreshQueue() { rpc("queue.list").then((r) => showQueue(r.queue)).catch(() => {}); }

function showQueue(queue) {
  const ol = $("queue"); ol.innerHTML = "";
  for (const q of queue) {
    const li = document.createElement("li");
    const s = document.createElement("span"); s.textContent = q.name + " - " + q.state + (q.message ? ": " + q.message : "");
    li.append(s);
    if (!["CHECKING", "RUNNING"].includes(q.state)) {
      const b = document.createElement("button"); b.textContent = "Remove";
      b.onclick = () => act("queue.remove", {id: q.id}).then((r) => showQueue(r.queue)); li.append(b);
    }
    ol.append(li);
  }
}
$("queue-next").onclick = () => act("queue.start_next").then((r) => { showPreview(r.entry.name); refreshQueue(); });
$("queue-clear").onclick = () => act("queue.clear_finished").then((r) => showQueue(r.queue));

connect();
