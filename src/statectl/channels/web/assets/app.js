// statectl dashboard: one EventSource, one card per device, no dependencies.
"use strict";

const devices = new Map(); // name -> {card, state}

function el(tag, attrs, ...children) {
  const node = document.createElement(tag);
  for (const [k, v] of Object.entries(attrs || {})) node.setAttribute(k, v);
  for (const c of children) node.append(c);
  return node;
}

function card(state) {
  const safe = state.name.replace(/[^A-Za-z0-9_-]/g, "_");
  const section = el("section", { class: "device", "data-device": state.name });
  const active = el("span", { class: "active-states", id: "state-" + safe });
  section.append(el("h2", {}, state.shown.name + " ", active));
  const diagram = el("div", { class: "diagram", title: "click: whole chart / readable size" });
  diagram.addEventListener("click", () => diagram.classList.toggle("fit"));
  section.append(diagram);
  fetch("/api/diagram/" + encodeURIComponent(state.name) + ".svg")
    .then((r) => r.text())
    .then((svg) => {
      // The SVG is rendered by the server from the model; names in it are escaped there.
      diagram.innerHTML = svg;
      // Its natural width in CSS pixels (Graphviz writes pt): the CSS scales the diagram to
      // the card but not below 0.6 of it (style.css, .diagram svg).
      const drawn = diagram.querySelector("svg");
      if (drawn && drawn.width.baseVal.value > 0) {
        drawn.style.setProperty("--natural", drawn.width.baseVal.value + "px");
      }
      highlight(devices.get(state.name));
    });
  section.append(el("table", { class: "invokes" }));
  section.append(el("div", { class: "monitors" }));
  section.append(el("div", { class: "counts" }));
  document.getElementById("devices").append(section);
  const option = el("option", { value: state.name });
  option.textContent = state.shown.name;
  document.getElementById("post-device").append(option);
  return { card: section, active, diagram, state };
}

function highlight(entry) {
  if (!entry) return;
  const ids = new Set(entry.state.active_ids);
  for (const g of entry.diagram.querySelectorAll("g.node, g.cluster")) {
    const title = g.querySelector("title");
    if (!title) continue;
    const id = title.textContent.replace(/^cluster_/, "");
    g.classList.toggle("active", ids.has(id));
  }
}

function show(state) {
  let entry = devices.get(state.name);
  if (!entry) {
    entry = card(state);
    devices.set(state.name, entry);
  }
  entry.state = state;
  entry.active.textContent = state.shown.active.join(", ");
  entry.card.dataset.active = state.active.join(",");
  const table = entry.card.querySelector("table.invokes");
  table.replaceChildren(el("tr", {}, el("th", {}, "invoke"), el("th", {}, "name"),
    el("th", {}, "observer method"), el("th", {}, "observer")));
  for (const i of state.invokes) {
    table.append(el("tr", {}, el("td", {}, "#" + i.number), el("td", {}, i.name),
      el("td", {}, i.method + "()"), el("td", {}, i.observer || "none")));
  }
  const monitors = entry.card.querySelector(".monitors");
  monitors.replaceChildren();
  for (const m of state.monitors) {
    const cls = m.status.startsWith("fault") ? "monitor-fault"
      : m.status === "running" ? "monitor-running" : "monitor-idle";
    monitors.append(el("div", { class: cls }, "monitor " + m.state + ": " + m.status));
  }
  entry.card.querySelector(".counts").textContent =
    state.events_processed + " events, " + state.invokes_issued + " invokes, " +
    state.observer_calls + " observer calls";
  highlight(entry);
  const list = document.getElementById("post-events");
  if (document.getElementById("post-device").value === state.name || devices.size === 1) {
    const shown = state.events_shown || state.events;
    list.replaceChildren(...state.events.map((e, k) => el("option", { value: e, label: shown[k] })));
  }
}

function log(message) {
  const list = document.getElementById("log");
  const item = el("li", { class: "kind-" + message.kind });
  item.textContent = message.text;
  list.append(item);
  while (list.children.length > 500) list.firstChild.remove();
  list.scrollTop = list.scrollHeight;
}

function connect() {
  const status = document.getElementById("connection");
  const source = new EventSource("/api/events");
  source.onopen = () => { status.textContent = "live"; status.className = "on"; };
  source.onerror = () => { status.textContent = "reconnecting…"; status.className = "off"; };
  source.onmessage = (e) => {
    const message = JSON.parse(e.data);
    if (message.type === "snapshot") {
      for (const d of message.devices) show(d);
    } else if (message.type === "record") {
      log(message);
      // A record carries what a step changes; the rest (events, invokes) is the snapshot's.
      const known = devices.get(message.state.name);
      show(known ? { ...known.state, ...message.state } : message.state);
    }
  };
}

document.getElementById("post-form").addEventListener("submit", async (e) => {
  e.preventDefault();
  const status = document.getElementById("post-status");
  const raw = document.getElementById("post-data").value.trim();
  let data = null;
  try {
    data = raw ? JSON.parse(raw) : null;
  } catch (err) {
    status.textContent = "data is not JSON: " + err.message;
    status.className = "refused";
    return;
  }
  const body = {
    device: document.getElementById("post-device").value || null,
    event: document.getElementById("post-event").value,
    data,
  };
  const headers = { "Content-Type": "application/json" };
  const token = document.getElementById("token").value;
  if (token) headers["X-Statectl-Token"] = token;
  const reply = await fetch("/api/post", { method: "POST", headers, body: JSON.stringify(body) });
  const answer = await reply.json();
  if (reply.ok) {
    status.textContent = "accepted " + body.event + (answer.seq ? " #" + answer.seq : "") +
      (answer.durable ? " (durable)" : "");
    status.className = "ok";
  } else {
    status.textContent = "refused (" + reply.status + "): " + answer.error;
    status.className = "refused";
  }
});

connect();
