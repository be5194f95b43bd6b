// The live view of `ferret serve`: the watched trial on its floor plan, the selected deployment's
// strategies and choices, updated from the server's event stream (GET /events).
//
// The requests follow the pattern the server is sized for (docs/serve.md, "A live view in the
// browser"): a few GETs on load, then one refetch per change that events announce, coalesced, and
// never a polling loop. The page is served with a strict Content-Security-Policy, so there is no
// inline script or style here: elements get classes and SVG presentation attributes only.
"use strict";

(() => {
  const TOKEN_KEY = "ferret-serve-token";
  const SVGNS = "http://www.w3.org/2000/svg";
  // Between reconnections of the event stream; reset once the server says hello.
  const BACKOFF_MS = [500, 1000, 2000, 4000, 8000, 15000];
  const DEPLOYMENT_REFETCH_GAP_MS = 500;
  const SCENES_KEPT = 8;
  // A categorical palette without reds and yellows, which the likelihood scale uses.
  const STRATEGY_COLOURS = [
    "#1f77b4",
    "#2ca02c",
    "#9467bd",
    "#17becf",
    "#8c564b",
    "#e377c2",
    "#7f7f7f",
    "#bcbd22",
    "#393b79",
    "#637939",
  ];
  const ROOM_FILLS = ["#eaf1fb", "#efeafa", "#e8f5ec", "#fbf1e2", "#f8e9ef", "#e6f4f5", "#f2f2e6"];
  // YlOrRd, applied to the square root of the likelihood so that the small probabilities of a
  // house with many containers still differ from one another.
  const LIKELIHOOD_STOPS = [
    [0, [255, 255, 204]],
    [0.25, [254, 217, 118]],
    [0.5, [253, 141, 60]],
    [0.75, [227, 26, 28]],
    [1, [128, 0, 38]],
  ];
  const NO_LIKELIHOOD = "#c4c8cf";
  // Where a task brings what it found: purple, unlike the start (green) and every route.
  const DESTINATION = "#7e22ce";

  const $ = (id) => document.getElementById(id);
  // A team's robots, in the trial's order: the first is the one robot's blue.
  const ROBOT_COLOURS = ["#1d4ed8", "#c2410c", "#047857", "#7c3aed"];
  // A robot not heard from for this long is marked silent: a minute by default, as a robot
  // reports at every container; `?silent=<seconds>` in the page's address says otherwise.
  const SILENT_AFTER_S = (() => {
    const v = Number(new URLSearchParams(location.search).get("silent"));
    return Number.isFinite(v) && v > 0 ? v : 60;
  })();

  // Everything the page knows. `epoch` changes with every start (a new token, a refusal), and
  // answers to requests of an older epoch are dropped, so nothing of a refused session shows.
  // What the page read from the server: emptied by `clearAll` when the token is refused.
  function shown() {
    return {
      loaded: false,
      backoff: 0,
      droppedSinceLoad: false,
      shared: null,
      scenes: [],
      sceneCache: new Map(),
      // Each scene's map (its occupancy grid, drawn once into an image), by scene name.
      maps: new Map(),
      deployments: [],
      depId: null,
      depPicked: false,
      dep: null,
      // While the deployment is read: the events that came meanwhile.
      depReading: null,
      live: new Map(),
      watchedId: null,
      follow: true,
      view: null,
      viewBusy: false,
      pending: [],
      scene: null,
    };
  }

  const S = {
    epoch: 0,
    token: "",
    stream: null,
    opening: null,
    streams: new Set(),
    retryTimer: null,
    lastError: "",
    abandoning: null,
    ...shown(),
  };

  class Stale extends Error {}
  class HttpError extends Error {
    constructor(status, message) {
      super(message);
      this.status = status;
    }
  }

  // Drawing waits for the next frame, once however many events asked for it: a burst of a
  // robot's events costs one drawing of the deployment per frame, not one per event (with a few
  // hundred trials on the curve, drawing at every event left the page seconds behind).
  function perFrame(draw) {
    let asked = false;
    return () => {
      if (asked) return;
      asked = true;
      requestAnimationFrame(() => {
        asked = false;
        draw();
      });
    };
  }

  const renderDeployment = perFrame(() => drawDeployment());
  const renderDeploymentSelect = perFrame(() => drawDeploymentSelect());
  const renderCurve = perFrame(() => drawCurve());
  const renderOpenTrials = perFrame(() => drawOpenTrials());

  // ---------------------------------------------------------------- requests

  function headers() {
    const h = { Accept: "application/json" };
    if (S.token) h.Authorization = "Bearer " + S.token;
    return h;
  }

  async function api(path, body) {
    const epoch = S.epoch;
    const init = { headers: headers(), cache: "no-store" };
    if (body !== undefined) {
      init.method = "POST";
      init.headers["Content-Type"] = "application/json";
      init.body = JSON.stringify(body);
    }
    const res = await fetch(path, init);
    if (epoch !== S.epoch) throw new Stale();
    if (res.status === 401) {
      refuse();
      throw new Stale();
    }
    if (!res.ok) {
      let message = res.statusText;
      try {
        message = (await res.json()).error.message;
      } catch (_) {
        // not the server's JSON error; the status says enough
      }
      throw new HttpError(res.status, `${path}: ${res.status} ${message}`);
    }
    const reply = await res.json();
    if (epoch !== S.epoch) throw new Stale();
    return reply;
  }

  const seg = (v) => encodeURIComponent(String(v));

  function showError(e) {
    if (e instanceof Stale) return;
    S.lastError = e && e.message ? e.message : String(e);
    const el = $("load-error");
    el.textContent = "Could not load " + S.lastError;
    el.hidden = false;
  }

  function clearError() {
    $("load-error").hidden = true;
  }

  // One request at a time per kind: a trigger while one is in flight asks for exactly one more
  // after it, however many triggers came; `gapMs` spaces the requests at least that far apart.
  function coalesced(fn, gapMs) {
    let busy = false;
    let again = false;
    let last = -Infinity;
    async function go() {
      busy = true;
      const wait = last + gapMs - performance.now();
      if (wait > 0) await new Promise((r) => setTimeout(r, wait));
      again = false;
      last = performance.now();
      try {
        await fn();
        clearError();
      } catch (e) {
        showError(e);
      }
      busy = false;
      if (again) go();
    }
    return () => {
      if (busy) again = true;
      else go();
    };
  }

  const refetchList = coalesced(fetchList, 0);
  const refetchDeployment = coalesced(fetchDeployment, DEPLOYMENT_REFETCH_GAP_MS);
  const refetchView = coalesced(fetchView, 0);

  // Each scene is read once and kept; only the most recently watched few, as a house's distance
  // table grows with the square of its containers and a page may stay open for weeks.
  function getScene(name) {
    let p = S.sceneCache.get(name);
    if (p) {
      S.sceneCache.delete(name);
    } else {
      p = api(`/scenes/${seg(name)}`);
      p.catch(() => {
        if (S.sceneCache.get(name) === p) S.sceneCache.delete(name);
      });
    }
    S.sceneCache.set(name, p);
    while (S.sceneCache.size > SCENES_KEPT) S.sceneCache.delete(S.sceneCache.keys().next().value);
    return p;
  }

  // A scene's occupancy grid as an image, read once per scene and kept as long as the scene
  // is: the plan draws it under the rooms' outlines once it has come.
  function getMap(name) {
    if (S.maps.has(name)) return;
    S.maps.set(name, null);
    const epoch = S.epoch;
    api(`/scenes/${seg(name)}/map`)
      .then((m) => {
        if (epoch !== S.epoch) return;
        S.maps.set(name, mapImage(m));
        while (S.maps.size > SCENES_KEPT) S.maps.delete(S.maps.keys().next().value);
        if (S.scene && S.scene.name === name) renderPlan();
      })
      .catch(() => {
        // A scene without a grid, or a server older than maps: the plan goes without.
        if (epoch === S.epoch) S.maps.set(name, { none: true });
      });
  }

  // Cell kinds as drawn: outside and free floor transparent (the room's fill shows), walls
  // dark, furniture and the robot's clearance around it shaded.
  const MAP_COLOURS = [
    [0, 0, 0, 0],
    [51, 65, 85, 255],
    [120, 113, 108, 150],
    [148, 163, 184, 60],
    [0, 0, 0, 0],
  ];

  // The grid drawn one pixel per cell, rows flipped (the map's y grows north, the screen's
  // down), as an image the SVG can place: the Content-Security-Policy allows data: images.
  function mapImage(m) {
    const canvas = document.createElement("canvas");
    canvas.width = m.width;
    canvas.height = m.height;
    const ctx = canvas.getContext("2d");
    const img = ctx.createImageData(m.width, m.height);
    const counts = [0, 0, 0, 0, 0];
    const kinds = new Uint8Array(m.width * m.height);
    let i = 0;
    for (const [kind, n] of m.runs) {
      const colour = MAP_COLOURS[kind] || MAP_COLOURS[0];
      counts[kind] = (counts[kind] || 0) + n;
      kinds.fill(kind, i, Math.min(i + n, kinds.length));
      for (let j = 0; j < n; j++, i++) {
        const x = i % m.width;
        const row = m.height - 1 - Math.floor(i / m.width);
        img.data.set(colour, (row * m.width + x) * 4);
      }
    }
    ctx.putImageData(img, 0, 0);
    return { ...m, runs: undefined, counts, kinds, url: canvas.toDataURL("image/png") };
  }

  async function loadAll() {
    S.loaded = true;
    const epoch = S.epoch;
    try {
      S.scenes = await api("/scenes");
    } catch (e) {
      showError(e);
    }
    if (epoch === S.epoch) refetchList();
  }

  function resync() {
    refetchList();
    if (S.depId != null) refetchDeployment();
    if (S.watchedId != null) refetchView();
  }

  async function fetchList() {
    const list = await api("/deployments");
    S.deployments = list;
    const newest = list.length ? list[list.length - 1].id : null;
    const known = list.some((d) => d.id === S.depId);
    if (newest == null) {
      S.depId = null;
      S.dep = null;
      renderDeploymentSelect();
      renderDeployment();
      if (S.watchedId == null) await showSceneOnly();
      return;
    }
    renderDeploymentSelect();
    if ((!S.depPicked && newest !== S.depId) || !known) {
      selectDeployment(newest, false);
    }
  }

  function selectDeployment(id, picked) {
    S.depId = id;
    S.depPicked = picked;
    S.dep = null;
    S.follow = true;
    renderDeploymentSelect();
    renderDeployment();
    refetchDeployment();
    ensureStream();
  }

  // A trial's event on a deployment as the page holds it: the trial's row and the open trials.
  function applyToDeployment(dep, e) {
    let row = dep.trials.find((t) => t.trial === e.trial);
    if (!row) {
      row = { trial: e.trial, k: e.k, target: e.target, strategy: e.strategy, cost_m: null };
      dep.trials.push(row);
    }
    if (e.robot != null) row.robot = e.robot;
    // Every event says its robot reported.
    if (e.at != null && !(row.heardAt >= e.at)) row.heardAt = e.at;
    // An event older than what the row shows (a trial ended) changes nothing.
    if (row.status && row.status !== "searching" && e.status === "searching") return;
    row.status = e.status;
    if (e.status !== "searching") row.cost_m = e.cost_m;
    const open = new Set(dep.open_trials);
    if (e.status === "searching") open.add(e.trial);
    else open.delete(e.trial);
    dep.open_trials = [...open].sort((a, b) => a - b);
  }

  async function fetchDeployment() {
    const id = S.depId;
    if (id == null) return;
    // The server reads the deployment at some moment of this request: the events that come
    // meanwhile may be newer than what it returns, and are applied to it again. Without this a
    // read that crossed a robot's last trials put the page back on an earlier trial for good.
    const reading = [];
    S.depReading = reading;
    let dep;
    try {
      dep = await api(`/deployments/${seg(id)}`);
    } finally {
      if (S.depReading === reading) S.depReading = null;
    }
    if (id !== S.depId) return; // another was selected meanwhile; its own fetch follows
    const now = Date.now();
    for (const t of dep.trials) t.heardAt = t.heard_s_ago == null ? null : now - t.heard_s_ago * 1000;
    for (const e of reading) applyToDeployment(dep, e);
    S.dep = dep;
    const item = S.deployments.find((d) => d.id === id);
    if (item) {
      item.trials = dep.trials.length;
      item.open_trials = dep.open_trials.slice();
      renderDeploymentSelect();
    }
    renderDeployment();
    if (S.follow) followNewest();
  }

  // The trial a follower watches: the newest open one, but a trial still being searched is not
  // left for a newer one (with several robots, the view would jump at every start).
  function followNewest() {
    const dep = S.dep;
    if (!dep) return;
    const open = dep.open_trials.slice().sort((a, b) => a - b);
    const newestOpen = open.length ? open[open.length - 1] : null;
    const watchedHere = watchedInDeployment();
    if (newestOpen != null && (!watchedHere || watchedEnded())) {
      if (newestOpen !== S.watchedId) watch(newestOpen, false);
      return;
    }
    // Every robot done: the follower rests on the deployment's last trial, not on whichever of
    // several robots' trials it watched last.
    if (newestOpen == null && watchedHere && watchedEnded()) {
      const last = dep.trials.reduce((a, t) => (!a || t.k > a.k ? t : a), null);
      if (last && last.trial !== S.watchedId) watch(last.trial, false);
      return;
    }
    if (!watchedHere) {
      const trials = dep.trials.slice().sort((a, b) => a.k - b.k);
      if (trials.length) {
        watch(trials[trials.length - 1].trial, false);
      } else {
        S.watchedId = null;
        S.view = null;
        showSceneOnly().catch(showError);
      }
    }
  }

  function watchedInDeployment() {
    return S.watchedId != null && !!S.dep && S.dep.trials.some((t) => t.trial === S.watchedId);
  }

  function watchedEnded() {
    if (S.watchedId == null) return true;
    const ev = S.live.get(S.watchedId);
    if (ev) return ev.status !== "searching";
    return !!(S.view && S.view.trial.trial === S.watchedId && S.view.trial.status !== "searching");
  }

  function watch(id, picked) {
    if (picked) S.follow = false;
    S.watchedId = id;
    S.pending = S.pending.filter((e) => e.trial === id);
    for (const [t, ev] of S.live) if (t !== id && ev.status !== "searching") S.live.delete(t);
    renderFollow();
    renderOpenTrials();
    renderCurve();
    refetchView();
  }

  // The watched trial's picture. Its events that arrive meanwhile wait, and are applied to it
  // once it is in (those it holds already change nothing).
  async function fetchView() {
    const id = S.watchedId;
    if (id == null) return;
    S.viewBusy = true;
    let again = false;
    try {
      const view = await api(`/trials/${seg(id)}/view`);
      const scene = await getScene(view.trial.scene);
      if (id !== S.watchedId) return;
      S.view = view;
      S.scene = scene;
      const pending = S.pending.filter((e) => e.trial === id);
      S.pending = [];
      again = !pending.every(applyStep);
      const t = view.trial;
      again = again || (t.status === "done" && !t.replays_m);
      renderTrial();
      renderPlan();
      renderOpenTrials();
      renderCurve();
    } finally {
      S.viewBusy = false;
    }
    if (again) refetchView();
  }

  // Before any trial: the first scene's plan, so that a wall screen shows the house.
  async function showSceneOnly() {
    if (S.view || !S.scenes.length) {
      renderTrial();
      return;
    }
    const scene = await getScene(S.scenes[0].name);
    if (S.view || S.watchedId != null) return;
    S.scene = scene;
    renderTrial();
    renderPlan();
  }

  // ---------------------------------------------------------------- the event stream

  function setConnection(state, text, title) {
    const el = $("connection");
    el.dataset.state = state;
    el.textContent = text;
    el.title = title || "";
    // While cut off, what the page shows may be out of date: it is dimmed until the stream is
    // back and read again.
    $("view").dataset.stale = String(state === "reconnecting");
  }

  // The stream follows the selected deployment: once the page shows one, only that deployment's
  // trials (and every new deployment) come to it (`/events?deployment=ID`), so a busy fleet's
  // other deployments cost this page nothing.
  function eventsPath(dep) {
    return dep == null ? "/events" : `/events?deployment=${seg(dep)}`;
  }

  function ensureStream() {
    // A retry is due: it opens the stream wanted then.
    if (S.retryTimer != null) return;
    const current = S.opening || S.stream;
    if (current && current.dep === S.depId) return;
    if (!current && !S.loaded) return;
    openStream(S.depId);
  }

  async function openStream(dep) {
    const epoch = S.epoch;
    const me = { ctrl: new AbortController(), dep, draining: false };
    S.opening = me;
    S.streams.add(me);
    let res;
    try {
      res = await fetch(eventsPath(dep), {
        headers: { ...headers(), Accept: "text/event-stream" },
        cache: "no-store",
        signal: me.ctrl.signal,
      });
    } catch (e) {
      S.streams.delete(me);
      if (epoch === S.epoch && S.opening === me) {
        S.opening = null;
        dropStream();
        streamDown(epoch, 0, "no connection");
      }
      return;
    }
    if (epoch !== S.epoch || S.opening !== me) {
      // Another deployment was selected meanwhile: its own stream is on the way.
      closeStream(me);
      return;
    }
    S.opening = null;
    if (res.status === 401) {
      closeStream(me);
      refuse();
      return;
    }
    if (!res.ok || !res.body) {
      closeStream(me);
      // Past the server's cap the stream this one was to replace holds the slot it needs: it
      // is given up too, and what passes meanwhile is read again once a stream is back.
      dropStream();
      const retryAfter = Number(res.headers.get("Retry-After")) || 0;
      const why = res.status === 503 ? "the server has too many open views" : `HTTP ${res.status}`;
      streamDown(epoch, retryAfter, why);
      return;
    }
    // The subscription exists once the headers are in. The stream this one replaces is read a
    // moment longer, for the events it had on the way; both may carry the same event, which is
    // then shown once.
    const old = S.stream;
    S.stream = me;
    if (old) {
      old.draining = true;
      setTimeout(() => closeStream(old), 1000);
    }
    $("connection").dataset.stream = dep == null ? "all" : String(dep);
    if (!old) setConnection("live", liveText(), liveTitle());
    // What is fetched from here on misses no event; after a drop, whatever changed meanwhile is
    // fetched again.
    if (!S.loaded) loadAll();
    else if (S.droppedSinceLoad) resync();
    S.droppedSinceLoad = false;
    try {
      await readEvents(res.body, epoch, me);
    } catch (_) {
      // a dropped connection: reconnect below
    }
    S.streams.delete(me);
    if (epoch === S.epoch && S.stream === me) {
      S.stream = null;
      streamDown(epoch, 0, "the stream ended");
    }
  }

  function closeStream(st) {
    st.draining = false;
    st.ctrl.abort();
    S.streams.delete(st);
  }

  function dropStream() {
    if (S.stream) {
      const old = S.stream;
      S.stream = null;
      closeStream(old);
    }
  }

  const liveText = () => (S.shared ? "live · every replica" : "live");
  const liveTitle = () =>
    S.shared
      ? "event stream open; trials served by every replica of this database arrive"
      : "event stream open";

  function streamDown(epoch, retryAfterS, why) {
    S.droppedSinceLoad = true;
    if (!S.loaded) loadAll();
    const base = BACKOFF_MS[Math.min(S.backoff, BACKOFF_MS.length - 1)];
    const delay = Math.max(base * (0.8 + 0.4 * Math.random()), retryAfterS * 1000);
    S.backoff += 1;
    const secs = Math.max(1, Math.round(delay / 1000));
    setConnection("reconnecting", `reconnecting (${secs} s)`, `${why}; trying again in ${secs} s`);
    clearTimeout(S.retryTimer);
    S.retryTimer = setTimeout(() => {
      S.retryTimer = null;
      if (epoch === S.epoch) openStream(S.depId);
    }, delay);
  }

  // Server-Sent Events read by hand: EventSource cannot send the Authorization header.
  async function readEvents(body, epoch, me) {
    const reader = body.pipeThrough(new TextDecoderStream()).getReader();
    let buf = "";
    let type = "";
    let data = [];
    for (;;) {
      const { value, done } = await reader.read();
      if (done || epoch !== S.epoch || (S.stream !== me && !me.draining)) return;
      buf += value;
      let nl;
      while ((nl = buf.indexOf("\n")) >= 0) {
        const line = buf.slice(0, nl).replace(/\r$/, "");
        buf = buf.slice(nl + 1);
        if (line === "") {
          if (data.length) dispatch(type || "message", data.join("\n"));
          type = "";
          data = [];
        } else if (!line.startsWith(":")) {
          const colon = line.indexOf(":");
          const field = colon < 0 ? line : line.slice(0, colon);
          let val = colon < 0 ? "" : line.slice(colon + 1);
          if (val.startsWith(" ")) val = val.slice(1);
          if (field === "event") type = val;
          else if (field === "data") data.push(val);
        }
      }
    }
  }

  function dispatch(type, raw) {
    let d;
    try {
      d = JSON.parse(raw);
    } catch (_) {
      return;
    }
    if (type === "hello") {
      S.backoff = 0;
      S.shared = !!d.shared;
      setConnection("live", liveText(), liveTitle());
    } else if (type === "trial") {
      onTrialEvent(d);
    } else if (type === "deployment") {
      refetchList();
    } else if (type === "resync") {
      resync();
    }
  }

  function onTrialEvent(e) {
    e.at = Date.now();
    const isNew = !S.live.has(e.trial);
    S.live.set(e.trial, e);
    const item = S.deployments.find((d) => d.id === e.deployment);
    if (!item) {
      refetchList();
    } else {
      const open = new Set(item.open_trials || []);
      if (e.status === "searching") {
        if (!open.has(e.trial) && isNew && e.searched === 0) item.trials += 1;
        open.add(e.trial);
      } else {
        open.delete(e.trial);
      }
      item.open_trials = [...open].sort((a, b) => a - b);
      renderDeploymentSelect();
    }
    // A deployment being read may have been read before this event: it is applied again to
    // what the read returns.
    if (S.depReading && e.deployment === S.depId) S.depReading.push(e);
    if (S.dep && e.deployment === S.dep.id) {
      applyToDeployment(S.dep, e);
      renderDeployment();
      if (e.status !== "searching") refetchDeployment();
    }
    if (e.trial === S.watchedId) {
      followStep(e);
    } else if (
      S.follow &&
      e.deployment === S.depId &&
      e.status === "searching" &&
      (watchedEnded() || !watchedInDeployment())
    ) {
      watch(e.trial, false);
    }
    // Only the trials still searching and the watched one are kept.
    if (e.status !== "searching" && e.trial !== S.watchedId) S.live.delete(e.trial);
  }

  // A step of the watched trial, drawn from its event: the observation it reports, the leg the
  // robot drove to make it (the way to the next container the event before gave) and the way on.
  // What the page cannot be sure of (a missed event, a container other than the one proposed)
  // has the trial's picture read again instead; so has a trial done, for its replays.
  function followStep(e) {
    if (S.viewBusy || !S.view || S.view.trial.trial !== e.trial) {
      S.pending.push(e);
      if (!S.viewBusy) refetchView();
      return;
    }
    if (!applyStep(e)) {
      refetchView();
      return;
    }
    renderTrial();
    renderPlan();
    renderOpenTrials();
    const t = S.view.trial;
    if (t.status === "done" && !t.replays_m) refetchView();
  }

  // Applies `e` to the picture; false when it cannot follow from what is shown.
  function applyStep(e) {
    const v = S.view;
    // A team's step moves one robot of several, and claims change without one: read the picture.
    if (v.robot_routes) return false;
    const t = v.trial;
    const n = t.searched.length;
    if (e.searched < n || (e.searched === n && e.observed)) return true; // shown already
    if (e.searched === n) {
      // No search: a start, or a trial given up.
      if (e.status !== t.status) {
        t.status = e.status;
        t.cost_m = e.cost_m;
        if (e.status !== "searching") t.next = null;
      }
      return true;
    }
    const o = e.observed;
    if (e.searched !== n + 1 || !o || t.status !== "searching" || !t.next) return false;
    if (o.container !== t.next.container) return false;
    // An event too long to travel between replicas comes without the way on: read the picture.
    if (e.status === "searching" && e.next && !Array.isArray(e.next_path)) return false;
    // A target of several found changes what every other container may hold: read the picture.
    if (o.found && t.targets && t.targets.length > 1 && e.status === "searching") return false;
    const leg = t.next.path || [];
    v.route = v.route.length ? v.route.concat(leg.slice(1)) : leg.slice();
    v.observations.push({ container: o.container, found: o.found, objects: o.objects });
    t.searched.push(o.container);
    if (v.likelihoods) v.likelihoods[o.container] = o.found ? 1 : 0;
    t.status = e.status;
    t.cost_m = e.cost_m;
    t.next = e.next && e.status === "searching" ? nextFrom(e.next, e.next_path || []) : null;
    return true;
  }

  // The next container as a trial's `next` gives it, from the scene and the event's way there.
  function nextFrom(id, path) {
    const c = S.scene ? S.scene.containers.find((x) => x.id === id) : null;
    let d = 0;
    for (let i = 1; i < path.length; i++) {
      d += Math.hypot(path[i][0] - path[i - 1][0], path[i][1] - path[i - 1][1]);
    }
    return {
      container: id,
      type: c ? c.type : id,
      room: c ? c.room : null,
      x: c ? c.x : null,
      y: c ? c.y : null,
      distance_m: d,
      path,
    };
  }

  // ---------------------------------------------------------------- token

  function refuse() {
    const hadToken = !!S.token;
    stop();
    clearAll();
    // A first visit has tried no token yet: it is asked for, not refused.
    if (hadToken) setConnection("refused", "refused", "the server refused the token");
    else setConnection("token", "token needed", "this server needs a token");
    $("view").hidden = true;
    $("token-panel").hidden = false;
    const err = $("auth-error");
    err.textContent = hadToken
      ? "The server refused this token. Enter the token it was started with."
      : "This server needs a token (it was started with FERRET_SERVE_TOKEN). Enter it to see the live view.";
    err.dataset.kind = hadToken ? "refused" : "ask";
    err.setAttribute("role", hadToken ? "alert" : "status");
    err.hidden = false;
    $("token-input").value = "";
    $("token-input").focus();
  }

  // Ends everything of the current epoch: requests in flight are dropped when they answer.
  function stop() {
    S.epoch += 1;
    for (const st of [...S.streams]) closeStream(st);
    S.stream = null;
    S.opening = null;
    clearTimeout(S.retryTimer);
    S.retryTimer = null;
  }

  function clearAll() {
    Object.assign(S, shown());
    clearError();
    renderDeploymentSelect();
    renderDeployment();
    renderTrial();
    renderPlan();
  }

  function start() {
    stop();
    clearAll();
    $("token-panel").hidden = true;
    $("auth-error").hidden = true;
    $("view").hidden = false;
    setConnection("connecting", "connecting…", "");
    openStream(null);
  }

  function readToken() {
    try {
      return sessionStorage.getItem(TOKEN_KEY) || "";
    } catch (_) {
      return "";
    }
  }

  function saveToken(t) {
    try {
      if (t) sessionStorage.setItem(TOKEN_KEY, t);
      else sessionStorage.removeItem(TOKEN_KEY);
    } catch (_) {
      // storage switched off: the token lives as long as the page
    }
  }

  // ---------------------------------------------------------------- helpers for drawing

  function el(tag, attrs, text) {
    const e = document.createElement(tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (v == null || v === false) continue;
      if (k === "class") e.className = v;
      else e.setAttribute(k, v === true ? "" : String(v));
    }
    if (text != null) e.textContent = text;
    return e;
  }

  function svg(tag, attrs, text) {
    const e = document.createElementNS(SVGNS, tag);
    for (const [k, v] of Object.entries(attrs || {})) {
      if (v == null || v === false) continue;
      e.setAttribute(k, String(v));
    }
    if (text != null) e.textContent = text;
    return e;
  }

  function titled(node, text) {
    node.appendChild(svg("title", {}, text));
    return node;
  }

  const fmtM = (v) => (v == null || !Number.isFinite(v) ? "–" : v.toFixed(2));
  const pct = (p) =>
    p >= 0.995
      ? "100 %"
      : p < 0.001 && p > 0
        ? "<0.1 %"
        : (p * 100).toFixed(p < 0.1 ? 1 : 0) + " %";

  // "CounterTop" -> "Counter top", "TVStand" -> "TV stand", "DiningRoom" -> "Dining room".
  // "looking for a Mug", "looking for all of Mug, Apple, then to the start".
  function taskWords(trial) {
    const targets = trial.targets || [trial.target];
    const what =
      targets.length > 1
        ? `looking for ${trial.goal === "any" ? "any" : "all"} of ${targets.join(", ")}`
        : `looking for ${targets[0]}`;
    return trial.destination ? `${what}, then to ${destinationWords(trial.destination)}` : what;
  }

  // A task's destination as the page names it.
  function destinationWords(d) {
    if (d.kind === "start") return "the start";
    if (d.kind === "container") return containerWords(d.id);
    if (d.kind === "room") return `the ${roomWords(d.name)}`;
    return `(${fmtM(d.x)}, ${fmtM(d.y)})`;
  }

  function words(type) {
    const parts = String(type).match(/[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+/g);
    if (!parts) return String(type);
    return parts
      .map((p, i) => (i === 0 || (p.length > 1 && p === p.toUpperCase()) ? p : p.toLowerCase()))
      .join(" ");
  }

  // What a person calls a scene's rooms and containers: their types in words, numbered when a
  // type occurs more than once ("Bedroom 2", "Drawer 3"). Ids (ProcTHOR's `4|3`, `room|4`) are
  // for machines and show only in tooltips.
  function sceneNames(scene) {
    if (!scene) return { rooms: new Map(), containers: new Map() };
    if (scene.names) return scene.names;
    const numbered = (items, typeOf, idOf) => {
      const count = new Map();
      for (const it of items) count.set(typeOf(it), (count.get(typeOf(it)) || 0) + 1);
      const seen = new Map();
      const out = new Map();
      for (const it of items) {
        const t = typeOf(it);
        const n = (seen.get(t) || 0) + 1;
        seen.set(t, n);
        out.set(idOf(it), count.get(t) > 1 ? `${words(t)} ${n}` : words(t));
      }
      return out;
    };
    scene.names = {
      rooms: numbered(scene.rooms || [], (r) => r.type, (r) => r.name),
      containers: numbered(scene.containers || [], (c) => c.type, (c) => c.id),
    };
    return scene.names;
  }

  function roomWords(id, scene = S.scene) {
    const name = sceneNames(scene).rooms.get(id);
    return name ? name.toLowerCase() : String(id);
  }

  // A container as a person names it: "Drawer 3 in the bedroom 2"; its id when the scene
  // does not list it.
  function containerWords(id, scene = S.scene) {
    const names = sceneNames(scene);
    const name = names.containers.get(id);
    if (!name) return String(id);
    const c = scene.containers.find((x) => x.id === id);
    return c && c.room ? `${name} in the ${roomWords(c.room, scene)}` : name;
  }

  function likelihoodColour(p) {
    if (p == null || !Number.isFinite(p)) return NO_LIKELIHOOD;
    const t = Math.sqrt(Math.min(1, Math.max(0, p)));
    for (let i = 1; i < LIKELIHOOD_STOPS.length; i++) {
      const [t1, c1] = LIKELIHOOD_STOPS[i];
      const [t0, c0] = LIKELIHOOD_STOPS[i - 1];
      if (t <= t1) {
        const f = (t - t0) / (t1 - t0);
        const c = c0.map((v, j) => Math.round(v + f * (c1[j] - v)));
        return "#" + c.map((v) => v.toString(16).padStart(2, "0")).join("");
      }
    }
    return "#800026";
  }

  function strategyColour(strategy) {
    const list = S.dep ? S.dep.strategies : [];
    const i = list.indexOf(strategy);
    return STRATEGY_COLOURS[(i < 0 ? 0 : i) % STRATEGY_COLOURS.length];
  }

  const plural = (n, one, many) => `${n} ${n === 1 ? one : many || one + "s"}`;

  function ordinal(n) {
    const s = ["th", "st", "nd", "rd"];
    const v = n % 100;
    return n + (s[(v - 20) % 10] || s[v] || s[0]);
  }

  function insidePolygon(x, y, poly) {
    let inside = false;
    for (let i = 0, j = poly.length - 1; i < poly.length; j = i++) {
      const [xi, yi] = poly[i];
      const [xj, yj] = poly[j];
      if (yi > y !== yj > y && x < ((xj - xi) * (y - yi)) / (yj - yi) + xi) inside = !inside;
    }
    return inside;
  }

  const overlap = (a, b) =>
    Math.max(0, Math.min(a.x2, b.x2) - Math.max(a.x1, b.x1)) *
    Math.max(0, Math.min(a.y2, b.y2) - Math.max(a.y1, b.y1));

  // ---------------------------------------------------------------- the floor plan

  // How much a label's box (screen pixels) lies where a label should not: its area, in px²,
  // on the map's walls or outside the house (sampled every 3 px), plus 400 px² for each leader
  // line through it (a label a line strikes through is hard to read). A scene without a map counts
  // the leader lines only.
  function labelBlockers(map, t, leaders) {
    const kinds = map && map.kinds;
    const cellAt = (px, py) => {
      const mx = t.minX + (px - t.ox) / t.s;
      const my = t.maxY - (py - t.oy) / t.s;
      const col = Math.floor((mx - map.origin[0]) / map.resolution_m);
      const row = Math.floor((my - map.origin[1]) / map.resolution_m);
      if (col < 0 || row < 0 || col >= map.width || row >= map.height) return 0;
      return kinds[row * map.width + col];
    };
    const crosses = (b, [x1, y1, x2, y2]) => {
      for (let k = 1; k < 12; k++) {
        const x = x1 + ((x2 - x1) * k) / 12;
        const y = y1 + ((y2 - y1) * k) / 12;
        if (x > b.x1 && x < b.x2 && y > b.y1 && y < b.y2) return true;
      }
      return false;
    };
    return (b) => {
      let cost = 0;
      for (const l of leaders) if (crosses(b, l)) cost += 400;
      if (!kinds) return cost;
      for (let y = b.y1 + 1.5; y < b.y2; y += 3)
        for (let x = b.x1 + 1.5; x < b.x2; x += 3) {
          const k = cellAt(x, y);
          if (k === 0 || k === 1) cost += 9;
        }
      return cost;
    };
  }

  function renderPlan() {
    const plan = $("plan");
    plan.replaceChildren();
    const scene = S.scene;
    if (!scene) return;
    const W = Math.max(200, plan.clientWidth);
    const H = Math.max(200, plan.clientHeight);
    plan.setAttribute("viewBox", `0 0 ${W} ${H}`);

    const view = S.view && S.view.trial.scene === scene.name ? S.view : null;
    const trial = view ? view.trial : null;
    const xs = [];
    const ys = [];
    for (const r of scene.rooms) for (const [x, y] of r.polygon) (xs.push(x), ys.push(y));
    for (const c of scene.containers) (xs.push(c.x), ys.push(c.y));
    xs.push(scene.start[0]);
    ys.push(scene.start[1]);
    const minX = Math.min(...xs);
    const maxX = Math.max(...xs);
    const minY = Math.min(...ys);
    const maxY = Math.max(...ys);
    const margin = 28;
    const s = Math.min(
      (W - 2 * margin) / Math.max(maxX - minX, 1),
      (H - 2 * margin) / Math.max(maxY - minY, 1),
    );
    const ox = (W - s * (maxX - minX)) / 2;
    const oy = (H - s * (maxY - minY)) / 2;
    // Map frame: y grows north, so it is flipped for the screen.
    const X = (x) => ox + (x - minX) * s;
    const Y = (y) => oy + (maxY - y) * s;
    // The transform, for tests that check the drawing against the server's map.
    Object.assign(plan.dataset, { scale: s, ox, oy, minX, maxY });
    const pts = (list) => list.map(([x, y]) => `${X(x).toFixed(1)},${Y(y).toFixed(1)}`).join(" ");

    const gRooms = svg("g", { class: "rooms" });
    const gLinks = svg("g", { class: "links" });
    const gPaths = svg("g", { class: "paths" });
    const gMarks = svg("g", { class: "containers" });
    const gLabels = svg("g", { class: "labels" });
    plan.append(gRooms, gLinks, gPaths, gMarks, gLabels);

    scene.rooms.forEach((r, i) => {
      const poly = svg("polygon", {
        points: pts(r.polygon),
        fill: ROOM_FILLS[i % ROOM_FILLS.length],
        stroke: "#5b6577",
        "stroke-width": 2,
        "stroke-linejoin": "round",
        "data-room": r.name,
      });
      titled(poly, `${roomWords(r.name, scene)} (id ${r.name})`);
      gRooms.appendChild(poly);
    });
    // The map under the plan: walls, doors (gaps in them) and furniture as the planner sees them.
    getMap(scene.name);
    const map = S.maps.get(scene.name);
    if (map && map.url) {
      const [x0, y0] = map.origin;
      const image = svg("image", {
        class: "map",
        href: map.url,
        x: X(x0),
        y: Y(y0 + map.height * map.resolution_m),
        width: map.width * map.resolution_m * s,
        height: map.height * map.resolution_m * s,
        preserveAspectRatio: "none",
        "image-rendering": "pixelated",
        "data-width": map.width,
        "data-height": map.height,
        "data-walls": map.counts[1],
        "data-furniture": map.counts[2],
      });
      titled(image, `the planner's map: ${map.width} × ${map.height} cells of ${map.resolution_m} m`);
      gRooms.appendChild(image);
    }

    // Obstacles for label placement, in screen pixels.
    const taken = [];
    const markerR = Math.max(6, Math.min(10, s * 0.18));
    for (const c of scene.containers) {
      const cx = X(c.x);
      const cy = Y(c.y);
      taken.push({
        x1: cx - markerR - 2,
        y1: cy - markerR - 2,
        x2: cx + markerR + 2,
        y2: cy + markerR + 2,
      });
    }
    const sx = X(scene.start[0]);
    const sy = Y(scene.start[1]);
    taken.push({ x1: sx - 10, y1: sy - 10, x2: sx + 10, y2: sy + 10 });

    // Room labels: the spot inside the room farthest from its containers, top first.
    for (const r of scene.rooms) {
      const rx = r.polygon.map((p) => p[0]);
      const ry = r.polygon.map((p) => p[1]);
      const [x0, x1, y0, y1] = [Math.min(...rx), Math.max(...rx), Math.min(...ry), Math.max(...ry)];
      const label = svg("text", { class: "room-label", "text-anchor": "middle" }, words(r.type));
      gLabels.appendChild(label);
      const w = label.getComputedTextLength() + 6;
      const h = 14;
      let best = null;
      for (const fy of [0.9, 0.1, 0.5, 0.75, 0.25]) {
        for (const fx of [0.5, 0.25, 0.75]) {
          const mx = x0 + fx * (x1 - x0);
          const my = y0 + fy * (y1 - y0);
          if (!insidePolygon(mx, my, r.polygon)) continue;
          const box = {
            x1: X(mx) - w / 2,
            x2: X(mx) + w / 2,
            y1: Y(my) - h / 2,
            y2: Y(my) + h / 2,
          };
          const hit = taken.reduce((a, b) => a + overlap(box, b), 0);
          if (!best || hit < best.hit) best = { box, hit };
          if (hit === 0) break;
        }
        if (best && best.hit === 0) break;
      }
      if (!best) {
        label.remove();
        continue;
      }
      label.setAttribute("x", ((best.box.x1 + best.box.x2) / 2).toFixed(1));
      label.setAttribute("y", (best.box.y2 - 3).toFixed(1));
      taken.push(best.box);
    }

    // Access points, and a thin line to each from its container (kept, so labels avoid them).
    const leaders = [];
    for (const c of scene.containers) {
      if (!c.access) continue;
      const ax = X(c.access[0]);
      const ay = Y(c.access[1]);
      leaders.push([X(c.x), Y(c.y), ax, ay]);
      gLinks.appendChild(
        svg("line", {
          x1: X(c.x),
          y1: Y(c.y),
          x2: ax,
          y2: ay,
          stroke: "#9aa3b2",
          "stroke-width": 1,
        }),
      );
      const d = 3.5;
      const ap = svg("polygon", {
        class: "access",
        points: `${ax},${ay - d} ${ax + d},${ay} ${ax},${ay + d} ${ax - d},${ay}`,
        fill: "#6b7280",
        "data-access": c.id,
      });
      titled(ap, `access point of ${containerWords(c.id, scene)}: where the robot stands to search it`);
      gLinks.appendChild(ap);
    }

    // The start pose: an arrow along its yaw.
    const yaw = (scene.start[2] * Math.PI) / 180;
    const ux = Math.cos(yaw);
    const uy = -Math.sin(yaw);
    const start = svg("polygon", {
      id: "start-pose",
      points: [
        [sx + 11 * ux, sy + 11 * uy],
        [sx - 7 * ux - 6 * uy, sy - 7 * uy + 6 * ux],
        [sx - 7 * ux + 6 * uy, sy - 7 * uy - 6 * ux],
      ]
        .map((p) => p.map((v) => v.toFixed(1)).join(","))
        .join(" "),
      fill: "#15803d",
      stroke: "#fff",
      "stroke-width": 1.5,
    });
    titled(start, `start pose (${scene.start[0]}, ${scene.start[1]}, ${scene.start[2]}°)`);
    gMarks.appendChild(start);

    // The route so far and the path to the next container.
    if (view && view.route && view.route.length > 1) {
      const route = svg("polyline", {
        id: "route",
        points: pts(view.route),
        fill: "none",
        stroke: "#1d4ed8",
        "stroke-width": 3.5,
        "stroke-linejoin": "round",
        "stroke-linecap": "round",
        "stroke-opacity": 0.85,
        "data-points": view.route.length,
      });
      titled(route, `route so far: ${fmtM(trial.cost_m)} m`);
      gPaths.appendChild(route);
    }
    // A team's robots: each one's way so far, where it is, and the way to its claim.
    const team = (view && view.robot_routes) || [];
    team.forEach((r, i) => {
      const colour = ROBOT_COLOURS[i % ROBOT_COLOURS.length];
      if (r.route.length > 1) {
        const way = svg("polyline", {
          class: "robot-route",
          points: pts(r.route),
          fill: "none",
          stroke: colour,
          "stroke-width": 3.5,
          "stroke-linejoin": "round",
          "stroke-linecap": "round",
          "stroke-opacity": 0.85,
          "data-robot": r.id,
          "data-points": r.route.length,
        });
        titled(way, `robot ${r.id}: its way so far`);
        gPaths.appendChild(way);
      }
      if (r.claim_path && r.claim_path.length > 1) {
        const state = (trial.robots || []).find((x) => x.id === r.id) || {};
        const claim = svg("polyline", {
          class: "claim-path",
          points: pts(r.claim_path),
          fill: "none",
          stroke: colour,
          "stroke-width": 2.5,
          "stroke-dasharray": "7 5",
          "stroke-linecap": "round",
          "data-robot": r.id,
          "data-container": state.claim || "",
        });
        titled(claim, `robot ${r.id} is heading to ${containerWords(state.claim, scene)}`);
        gPaths.appendChild(claim);
      }
    });
    const next = trial && trial.status === "searching" && !team.length ? trial.next : null;
    if (next && next.path && next.path.length > 1) {
      const path = svg("polyline", {
        id: "next-path",
        points: pts(next.path),
        fill: "none",
        stroke: "#0f172a",
        "stroke-width": 2.5,
        "stroke-dasharray": "7 5",
        "stroke-linecap": "round",
        "data-container": next.container,
        "data-points": next.path.length,
      });
      titled(
        path,
        `path to the next container, ${containerWords(next.container, scene)}: ${fmtM(next.distance_m)} m`,
      );
      gPaths.appendChild(path);
    }

    // Containers, coloured by likelihood while the search goes on (once it ended they say
    // nothing more: a red "62 %" beside a found target misleads), searched ones numbered.
    const likelihoods = shownLikelihoods(view);
    const obs = new Map();
    if (view) view.observations.forEach((o, i) => obs.set(o.container, { ...o, order: i + 1 }));
    const searchedOrder = new Map();
    if (trial) trial.searched.forEach((id, i) => searchedOrder.set(id, i + 1));
    const placed = [];
    for (const c of scene.containers) {
      const cx = X(c.x);
      const cy = Y(c.y);
      const order = searchedOrder.get(c.id);
      const o = obs.get(c.id);
      const found = !!(o && o.found);
      const isNext = !!(next && next.container === c.id);
      const p = likelihoods && c.id in likelihoods ? likelihoods[c.id] : null;
      const g = svg("g", {
        class: "container" + (isNext ? " is-next" : "") + (found ? " is-found" : ""),
        "data-container": c.id,
        "data-type": c.type,
        "data-searched": order ? "true" : "false",
        "data-found": found ? "true" : "false",
        "data-next": isNext ? "true" : "false",
        "data-likelihood": p == null ? "none" : String(p),
        "data-order": order || null,
      });
      if (isNext) {
        g.appendChild(
          svg("circle", {
            class: "next-ring",
            cx,
            cy,
            r: markerR + 7,
            fill: "none",
            stroke: "#0f172a",
            "stroke-width": 2.5,
          }),
        );
      }
      if (found) {
        g.appendChild(
          svg("circle", {
            cx,
            cy,
            r: markerR + 5,
            fill: "none",
            stroke: "#16a34a",
            "stroke-width": 4,
          }),
        );
      }
      g.appendChild(
        svg("circle", {
          class: "marker",
          cx,
          cy,
          r: markerR,
          fill: likelihoodColour(p),
          stroke: order ? "#111827" : "#4b5563",
          "stroke-width": order ? 2.5 : 1.5,
        }),
      );
      if (order) {
        const dark = p != null && p > 0.35;
        g.appendChild(
          svg(
            "text",
            {
              class: "order" + (dark ? " on-dark" : ""),
              x: cx,
              y: cy + 4,
              "text-anchor": "middle",
            },
            String(order),
          ),
        );
      }
      let tip = `${containerWords(c.id, scene)} (id ${c.id})`;
      if (p != null) tip += `\nlikelihood the target is here: ${pct(p)}`;
      if (order)
        tip +=
          `\nsearched ${ordinal(order)}` +
          (o ? `: ${found ? "FOUND the target" : "not there"}` : "");
      if (o && o.objects.length) tip += `\nseen: ${o.objects.join(", ")}`;
      if (isNext) tip += `\nnext to search, ${fmtM(next.distance_m)} m away`;
      titled(g, tip);
      gMarks.appendChild(g);
      const rank = isNext ? 0 : found ? 1 : order ? 2 : 3;
      placed.push({ c, cx, cy, p, order, found, isNext, rank });
    }

    // Container labels beside their markers, placed where they overlap nothing if they can: no
    // other label or marker, no leader line, and on the map neither a wall nor outside the house.
    placed.sort((a, b) => a.rank - b.rank || a.cy - b.cy || a.cx - b.cx);
    const d = markerR + 4;
    const blocked = labelBlockers(map, { s, ox, oy, minX, maxY }, leaders);
    for (const m of placed) {
      const text = svg("text", {
        class: "container-label" + (m.isNext ? " next" : "") + (m.found ? " found" : ""),
      });
      text.appendChild(svg("tspan", {}, sceneNames(scene).containers.get(m.c.id) || words(m.c.type)));
      if (m.found) text.appendChild(svg("tspan", { class: "pct" }, " · found"));
      // Near-zero likelihoods go without a number: the colour says it, and the labels stay short.
      else if (m.p != null && !m.order && m.p >= 0.005)
        text.appendChild(svg("tspan", { class: "pct" }, ` ${pct(m.p)}`));
      gLabels.appendChild(text);
      const w = text.getComputedTextLength();
      const h = 13;
      const spots = [
        [m.cx + d, m.cy + 4, "start"],
        [m.cx - d, m.cy + 4, "end"],
        [m.cx, m.cy - d - 3, "middle"],
        [m.cx, m.cy + d + 11, "middle"],
        [m.cx + d - 2, m.cy - d, "start"],
        [m.cx + d - 2, m.cy + d + 8, "start"],
        [m.cx - d + 2, m.cy - d, "end"],
        [m.cx - d + 2, m.cy + d + 8, "end"],
        [m.cx, m.cy - 2 * d - 3, "middle"],
        [m.cx, m.cy + 2 * d + 11, "middle"],
      ];
      let best = null;
      for (const [x, y, anchor] of spots) {
        const x1 = anchor === "start" ? x : anchor === "end" ? x - w : x - w / 2;
        const box = { x1: x1 - 1, x2: x1 + w + 1, y1: y - h + 2, y2: y + 3 };
        let hit = taken.reduce((a, b) => a + overlap(box, b), 0) + blocked(box);
        if (box.x1 < 2 || box.x2 > W - 2 || box.y1 < 2 || box.y2 > H - 2) hit += 1e6;
        if (!best || hit < best.hit) best = { x, y, anchor, box, hit };
        if (hit === 0) break;
      }
      text.setAttribute("x", best.x.toFixed(1));
      text.setAttribute("y", best.y.toFixed(1));
      text.setAttribute("text-anchor", best.anchor);
      text.setAttribute("data-container", m.c.id);
      taken.push(best.box);
    }

    // Where a task brings what it found: a green diamond.
    const dest = trial && trial.destination;
    if (dest && Array.isArray(dest.at)) {
      const dx = X(dest.at[0]);
      const dy = Y(dest.at[1]);
      const r = 9;
      const mark = svg("polygon", {
        id: "destination",
        points: `${dx},${dy - r} ${dx + r},${dy} ${dx},${dy + r} ${dx - r},${dy}`,
        fill: DESTINATION,
        stroke: "#fff",
        "stroke-width": 2,
        "data-kind": dest.kind,
      });
      titled(
        mark,
        `destination: ${destinationWords(dest)}` +
          (dest.distance_m != null ? `, ${fmtM(dest.distance_m)} m from the last container` : ""),
      );
      gMarks.appendChild(mark);
    }

    // Where each robot of a team is, named, and how long since it was heard from.
    team.forEach((r, i) => {
      const at = r.route[r.route.length - 1];
      const state = (trial.robots || []).find((x) => x.id === r.id) || {};
      const mark = svg("g", { class: "team-robot", "data-robot": r.id });
      mark.appendChild(
        svg("circle", {
          cx: X(at[0]),
          cy: Y(at[1]),
          r: 6,
          fill: ROBOT_COLOURS[i % ROBOT_COLOURS.length],
          stroke: "#fff",
          "stroke-width": 2,
        }),
      );
      // Robots standing together (at the start, say) get their names one above another.
      const near = team
        .slice(0, i)
        .filter((o) => Math.hypot(...o.route[o.route.length - 1].map((v, k) => v - at[k])) < 0.4)
        .length;
      mark.appendChild(
        svg(
          "text",
          { x: X(at[0]) + 9, y: Y(at[1]) - 8 - 13 * near, class: "robot-label" },
          r.id,
        ),
      );
      const heard =
        state.heard_s_ago == null ? "not heard from yet" : `heard ${state.heard_s_ago.toFixed(0)} s ago`;
      titled(
        mark,
        `robot ${r.id}: ${plural((state.searched || []).length, "search", "searches")}, ` +
          `${fmtM(state.cost_m)} m, ${state.claim ? `heading to ${containerWords(state.claim)}` : "no claim"}, ${heard}`,
      );
      gMarks.appendChild(mark);
    });

    // Where the robot is: the end of its route (the start before its first search).
    if (trial && !team.length) {
      const at = view.route && view.route.length ? view.route[view.route.length - 1] : scene.start;
      const robot = svg("circle", {
        id: "robot",
        cx: X(at[0]),
        cy: Y(at[1]),
        r: 6,
        fill: "#1d4ed8",
        stroke: "#fff",
        "stroke-width": 2,
      });
      titled(robot, "the robot, where it last reported");
      gMarks.appendChild(robot);
    }

    // A scale bar of a round number of metres, bottom left.
    const nice = [0.5, 1, 2, 5, 10, 20, 50].find((m) => m * s >= 60) || 50;
    const bx = 12;
    const by = H - 12;
    const bar = svg("g", { class: "scale-bar" });
    bar.appendChild(
      svg("path", {
        d: `M${bx},${by - 5}v5h${nice * s}v-5`,
        fill: "none",
        stroke: "#374151",
        "stroke-width": 1.5,
      }),
    );
    bar.appendChild(
      svg("text", { x: bx + (nice * s) / 2, y: by - 8, "text-anchor": "middle" }, `${nice} m`),
    );
    plan.appendChild(bar);
  }

  // ---------------------------------------------------------------- the legend

  // The likelihoods the plan colours containers by: only while the trial searches.
  function shownLikelihoods(view) {
    if (!view || view.trial.status !== "searching") return null;
    return view.likelihoods;
  }

  function renderLegend() {
    const box = $("legend");
    box.replaceChildren();
    if (!S.scene) return;
    const view = S.view;
    const hasLikelihoods = !!shownLikelihoods(view);
    const scale = el("div", {
      class: "legend-scale",
      id: "likelihood-legend",
      "data-likelihoods": hasLikelihoods ? "true" : "false",
    });
    if (hasLikelihoods) {
      const several = view.trial.targets && view.trial.targets.length > 1;
      scale.appendChild(
        el(
          "span",
          { class: "legend-title" },
          several ? "Likelihood a wanted target is there" : "Likelihood the target is there",
        ),
      );
      const w = 260;
      const pad = 16;
      const bar = svg("svg", { width: w + 2 * pad, height: 30, viewBox: `0 0 ${w + 2 * pad} 30` });
      const grad = svg("linearGradient", { id: "likelihood-gradient", x1: 0, x2: 1, y1: 0, y2: 0 });
      for (let i = 0; i <= 10; i++) {
        grad.appendChild(
          svg("stop", { offset: i / 10, "stop-color": likelihoodColour((i / 10) ** 2) }),
        );
      }
      bar.appendChild(svg("defs", {}).appendChild(grad).parentNode);
      bar.appendChild(
        svg("rect", {
          x: pad,
          y: 2,
          width: w,
          height: 12,
          fill: "url(#likelihood-gradient)",
          stroke: "#6b7280",
          "stroke-width": 0.5,
        }),
      );
      for (const p of [0, 0.05, 0.25, 0.5, 1]) {
        const x = pad + Math.sqrt(p) * w;
        bar.appendChild(svg("line", { x1: x, x2: x, y1: 14, y2: 18, stroke: "#374151" }));
        bar.appendChild(
          svg(
            "text",
            { x, y: 28, "text-anchor": "middle", class: "tick" },
            `${Math.round(p * 100)} %`,
          ),
        );
      }
      scale.appendChild(bar);
    } else {
      const sw = svg("svg", { width: 16, height: 16, viewBox: "0 0 16 16" });
      sw.appendChild(svg("circle", { cx: 8, cy: 8, r: 6, fill: NO_LIKELIHOOD, stroke: "#4b5563" }));
      scale.appendChild(sw);
      scale.appendChild(
        el(
          "span",
          {},
          !view
            ? "grey: no trial, no likelihoods"
            : view.trial.status !== "searching"
              ? `grey: the search has ended (${view.trial.status}); likelihoods show while it goes on`
              : `grey: ${view.trial.strategy} plans without likelihoods`,
        ),
      );
    }
    box.appendChild(scale);

    const items = el("div", { class: "legend-items" });
    const item = (draw, label) => {
      const s = svg("svg", { width: 30, height: 20, viewBox: "0 0 30 20" });
      draw(s);
      const span = el("span", { class: "legend-item" });
      span.append(s, document.createTextNode(label));
      items.appendChild(span);
    };
    item((s) => {
      s.appendChild(
        svg("circle", {
          cx: 15,
          cy: 10,
          r: 7,
          fill: likelihoodColour(0),
          stroke: "#111827",
          "stroke-width": 2.5,
        }),
      );
      s.appendChild(svg("text", { x: 15, y: 14, "text-anchor": "middle", class: "order" }, "1"));
    }, "searched, in order");
    item((s) => {
      s.appendChild(
        svg("circle", { cx: 15, cy: 10, r: 8, fill: "none", stroke: "#16a34a", "stroke-width": 3 }),
      );
      s.appendChild(svg("circle", { cx: 15, cy: 10, r: 5, fill: likelihoodColour(1) }));
    }, "found");
    item((s) => {
      s.appendChild(
        svg("circle", { cx: 15, cy: 10, r: 8, fill: "none", stroke: "#0f172a", "stroke-width": 2 }),
      );
      s.appendChild(svg("circle", { cx: 15, cy: 10, r: 4, fill: "#fed976", stroke: "#4b5563" }));
    }, "next");
    item(
      (s) =>
        s.appendChild(
          svg("line", {
            x1: 2,
            x2: 28,
            y1: 10,
            y2: 10,
            stroke: "#0f172a",
            "stroke-width": 2.5,
            "stroke-dasharray": "5 3",
          }),
        ),
      "path to next",
    );
    item((s) => {
      s.appendChild(
        svg("line", { x1: 2, x2: 22, y1: 10, y2: 10, stroke: "#1d4ed8", "stroke-width": 3.5 }),
      );
      s.appendChild(
        svg("circle", {
          cx: 23,
          cy: 10,
          r: 5,
          fill: "#1d4ed8",
          stroke: "#fff",
          "stroke-width": 1.5,
        }),
      );
    }, "route so far, robot");
    item(
      (s) => s.appendChild(svg("polygon", { points: "24,10 10,4 10,16", fill: "#15803d" })),
      "start",
    );
    item(
      (s) => s.appendChild(svg("polygon", { points: "15,6 19,10 15,14 11,10", fill: "#6b7280" })),
      "access point",
    );
    if (view && view.trial.destination) {
      item(
        (s) =>
          s.appendChild(
            svg("polygon", {
              points: "15,2 23,10 15,18 7,10",
              fill: DESTINATION,
              stroke: "#fff",
              "stroke-width": 1.5,
            }),
          ),
        "destination",
      );
    }
    box.appendChild(items);
  }

  // ---------------------------------------------------------------- the trial

  function renderTrial() {
    const view = S.view;
    const trial = view ? view.trial : null;
    const card = $("plan-card");
    card.dataset.trial = trial ? trial.trial : "";
    card.dataset.status = trial ? trial.status : "";
    const status = $("trial-status");
    status.textContent = trial ? trial.status : "";
    status.dataset.status = trial ? trial.status : "";

    if (!trial) {
      $("trial-title").textContent = S.scene
        ? `No trial yet · ${S.scene.name}`
        : S.loaded
          ? "No trial yet"
          : "";
      $("trial-summary").textContent = S.scene
        ? "The scene's floor plan; a robot's trial shows here as it searches."
        : S.loaded
          ? "Waiting for a robot to start a trial."
          : "";
      $("trial-facts").replaceChildren();
      $("trial-empty").hidden = !S.loaded;
      $("trial-body").hidden = true;
      $("next-container").hidden = true;
      delete $("next-container").dataset.container;
      $("searched-list").replaceChildren();
      $("replays-box").hidden = true;
      renderAbandon(null);
      renderLegend();
      renderFollow();
      return;
    }

    $("trial-empty").hidden = true;
    $("trial-body").hidden = false;
    renderAbandon(trial);
    const found = view.observations.find((o) => o.found);
    $("trial-title").textContent = `Trial ${trial.trial}: ${taskWords(trial)}`;
    const ended = trial.status !== "searching";
    $("trial-summary").textContent =
      `${trial.strategy} · deployment ${trial.deployment}, trial k = ${trial.k} · scene ${trial.scene} · ` +
      (ended
        ? `${trial.status === "done" ? "found" : trial.status} after ${fmtM(trial.cost_m)} m`
        : `${fmtM(trial.cost_m)} m so far`);

    const facts = $("trial-facts");
    facts.replaceChildren();
    const fact = (k, v, id) => {
      const dd = el("dd", { id });
      if (v instanceof Node) dd.append(v);
      else dd.textContent = v;
      facts.append(el("dt", {}, k), dd);
    };
    const targets = trial.targets || [trial.target];
    if (targets.length > 1 || trial.destination) {
      const dd = el("span", {});
      targets.forEach((t, i) => {
        const at = (trial.found_in || {})[t];
        if (i) dd.append(document.createTextNode(trial.goal === "any" ? " or " : ", "));
        dd.append(
          el(
            "span",
            {
              class: at ? "badge found" : "muted",
              "data-target": t,
              "data-found-in": at || "",
            },
            at ? `${t} ✓ ${containerWords(at)}` : t,
          ),
        );
      });
      fact(trial.goal === "any" ? "any of" : "all of", dd, "fact-target");
      if (trial.destination)
        fact("bring to", destinationWords(trial.destination), "fact-destination");
    } else {
      fact("target", trial.target, "fact-target");
    }
    fact("strategy", trial.strategy, "fact-strategy");
    if (trial.robots) {
      const list = el("span", {});
      trial.robots.forEach((r, i) => {
        if (i) list.append(document.createTextNode(", "));
        list.append(
          el(
            "span",
            {
              // The colour by class: the page's policy allows no inline style.
              class: `robot-badge robot-${i % ROBOT_COLOURS.length}`,
              "data-robot": r.id,
              "data-claim": r.claim || "",
            },
            `${r.id} ${r.claim ? "→ " + r.claim : "·"} ${fmtM(r.cost_m)} m`,
          ),
        );
      });
      fact("robots", list, "fact-robots");
    }
    fact(
      ended ? (trial.robots ? "makespan" : "cost") : "cost so far",
      `${fmtM(trial.cost_m)} m`,
      "fact-cost",
    );
    const total = S.scene ? S.scene.containers.length : null;
    fact(
      "searched",
      `${trial.searched.length}${total != null ? ` of ${total}` : ""}`,
      "fact-searched",
    );

    const nextEl = $("next-container");
    const next = ended ? null : trial.next;
    if (next) {
      nextEl.replaceChildren(
        el("strong", {}, "Next: "),
        document.createTextNode(
          `${containerWords(next.container)}, ${fmtM(next.distance_m)} m away`,
        ),
      );
      const p = view.likelihoods ? view.likelihoods[next.container] : null;
      if (p != null) nextEl.append(document.createTextNode(` · likelihood ${pct(p)}`));
      nextEl.dataset.container = next.container;
      nextEl.hidden = false;
    } else {
      nextEl.hidden = true;
      delete nextEl.dataset.container;
    }

    const list = $("searched-list");
    list.replaceChildren();
    const obs = new Map(view.observations.map((o) => [o.container, o]));
    for (const id of trial.searched) {
      const o = obs.get(id);
      const li = el("li", { "data-container": id, "data-found": o && o.found ? "true" : "false" });
      li.appendChild(el("span", { class: "what", title: `id ${id}` }, containerWords(id)));
      const here = Object.entries(trial.found_in || {})
        .filter(([, c]) => c === id)
        .map(([t]) => t);
      if (o && o.found)
        li.appendChild(
          el(
            "span",
            { class: "badge found" },
            `found ${here.length ? here.join(", ") : trial.target}`,
          ),
        );
      else li.appendChild(el("span", { class: "muted" }, " not there"));
      if (o && o.objects.length)
        li.appendChild(el("span", { class: "seen" }, `seen: ${o.objects.join(", ")}`));
      list.appendChild(li);
    }
    if (!trial.searched.length) list.appendChild(el("li", { class: "muted empty" }, "nothing yet"));
    if (found && !trial.searched.includes(found.container)) {
      list.appendChild(
        el("li", { "data-container": found.container }, `found in ${containerWords(found.container)}`),
      );
    }

    const box = $("replays-box");
    if (trial.replays_m && ended) {
      const body = $("replays").tBodies[0];
      body.replaceChildren();
      const rows = Object.entries(trial.replays_m).map(([strategy, cost]) => ({
        strategy,
        cost,
        own: strategy === trial.strategy,
      }));
      if (!(trial.strategy in trial.replays_m))
        rows.push({ strategy: trial.strategy, cost: trial.cost_m, own: true });
      rows.sort((a, b) => a.cost - b.cost);
      for (const r of rows) {
        const tr = el("tr", {
          "data-strategy": r.strategy,
          "data-cost": r.cost,
          class: r.own ? "own" : "",
        });
        tr.append(
          el("td", {}, r.strategy),
          el("td", {}, fmtM(r.cost)),
          el(
            "td",
            { class: "muted" },
            r.own
              ? "deployed"
              : `${r.cost - trial.cost_m >= 0 ? "+" : "−"}${fmtM(Math.abs(r.cost - trial.cost_m))}`,
          ),
        );
        body.appendChild(tr);
      }
      box.hidden = false;
    } else {
      box.hidden = true;
    }
    renderLegend();
    renderFollow();
  }

  function renderFollow() {
    $("follow-box").hidden = S.follow || !S.dep;
  }

  // ---------------------------------------------------------------- the deployment

  function drawDeploymentSelect() {
    const sel = $("deployment-select");
    const keep = document.activeElement === sel;
    sel.replaceChildren();
    for (const d of S.deployments.slice().reverse()) {
      const open = (d.open_trials || []).length;
      const label =
        `#${d.id} · ${d.selector} · ${plural(d.strategies.length, "strategy", "strategies")} · ${plural(d.trials, "trial")}` +
        (open ? `, ${open} open` : "");
      sel.appendChild(el("option", { value: d.id, selected: d.id === S.depId }, label));
    }
    if (S.depId != null) sel.value = String(S.depId);
    sel.disabled = !S.deployments.length;
    sel.closest("label").hidden = !S.deployments.length;
    if (keep) sel.focus();
  }

  function drawDeployment() {
    const dep = S.dep;
    const card = $("deployment-card");
    card.dataset.deployment = dep ? dep.id : "";
    const body = $("strategy-table").tBodies[0];
    body.replaceChildren();
    if (!dep) {
      $("deployment-title").textContent = "Deployment";
      $("deployment-summary").textContent =
        S.loaded && !S.deployments.length
          ? "No deployment yet: it shows here when a robot creates one."
          : "";
      $("next-strategy").textContent = "";
      $("deployment-body").hidden = true;
      renderCurve();
      renderOpenTrials();
      return;
    }
    $("deployment-body").hidden = false;
    const ended = dep.trials.filter((t) => t.status !== "searching").length;
    $("deployment-title").textContent = `Deployment ${dep.id}`;
    $("deployment-summary").textContent =
      `selector ${dep.selector}` +
      (dep.selector === "ucb" ? ` (c = ${dep.c})` : "") +
      ` · seed ${dep.seed}` +
      (dep.sequential ? " · one trial at a time" : "") +
      ` · ${plural(dep.trials.length, "trial")}, ${ended} ended, ${dep.open_trials.length} open`;
    // The server counts a strategy's ended trials; those it searches now are counted here.
    const searching = new Map();
    for (const t of dep.trials)
      if (t.status === "searching") searching.set(t.strategy, (searching.get(t.strategy) || 0) + 1);
    for (const r of dep.per_strategy) {
      const isNext = dep.next && dep.next.strategy === r.strategy;
      const tr = el("tr", {
        "data-strategy": r.strategy,
        class: isNext ? "next-pick" : "",
        title: isNext ? dep.next.why : null,
      });
      const name = el("td", { class: "strategy" });
      const sw = svg("svg", { width: 12, height: 12, viewBox: "0 0 12 12", class: "swatch" });
      sw.appendChild(svg("circle", { cx: 6, cy: 6, r: 5, fill: strategyColour(r.strategy) }));
      name.append(sw, document.createTextNode(r.strategy));
      if (isNext) name.appendChild(el("span", { class: "badge next" }, "next"));
      const count = el("td", { "data-deployed": r.deployed }, String(r.deployed));
      const now = searching.get(r.strategy) || 0;
      if (now) {
        count.dataset.searching = now;
        count.appendChild(el("span", { class: "searching" }, ` +${now} searching`));
      }
      tr.append(
        name,
        count,
        el("td", {}, fmtM(r.mean_cost_m)),
        el("td", {}, fmtM(r.replay_mean_m)),
        el("td", {}, fmtM(r.score)),
      );
      body.appendChild(tr);
    }
    $("next-strategy").textContent = dep.next ? `Next trial: ${dep.next.why}` : "";
    renderCurve();
    renderOpenTrials();
    renderFollow();
  }

  // The strategy chosen at each trial: one row per strategy, one mark per trial at x = k.
  function drawCurve() {
    const box = $("selection-curve");
    box.replaceChildren();
    const dep = S.dep;
    if (!dep) {
      box.setAttribute("height", 0);
      return;
    }
    const W = Math.max(240, $("curve-wrap").clientWidth);
    const rows = dep.strategies;
    const rowH = 22;
    const top = 16;
    const labelW = Math.min(190, Math.max(...rows.map((r) => r.length)) * 6.6 + 12);
    const H = top + rows.length * rowH + 26;
    box.setAttribute("viewBox", `0 0 ${W} ${H}`);
    box.setAttribute("height", H);
    const trials = dep.trials.slice().sort((a, b) => a.k - b.k);
    const maxK = Math.max(10, ...trials.map((t) => t.k));
    const x0 = labelW + 18;
    const x1 = W - 14;
    const X = (k) => x0 + ((k - 1) / Math.max(1, maxK - 1)) * (x1 - x0);
    const step = (x1 - x0) / Math.max(1, maxK - 1);
    rows.forEach((name, i) => {
      const y = top + i * rowH + rowH / 2;
      box.appendChild(svg("line", { x1: x0 - 4, x2: x1 + 4, y1: y, y2: y, stroke: "#e5e7eb" }));
      const t = svg(
        "text",
        {
          x: labelW,
          y: y + 4,
          "text-anchor": "end",
          class: "curve-label",
          fill: strategyColour(name),
        },
        name,
      );
      titled(t, name);
      box.appendChild(t);
    });
    // Axis: trial k.
    const axisY = top + rows.length * rowH + 4;
    box.appendChild(
      svg("line", { x1: x0 - 4, x2: x1 + 4, y1: axisY, y2: axisY, stroke: "#9ca3af" }),
    );
    const tickEvery =
      [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000].find((n) => n * step >= 28) || 1000;
    for (let k = 1; k <= maxK; k++) {
      if (k !== 1 && k % tickEvery) continue;
      box.appendChild(
        svg("line", { x1: X(k), x2: X(k), y1: axisY, y2: axisY + 4, stroke: "#9ca3af" }),
      );
      box.appendChild(
        svg("text", { x: X(k), y: axisY + 15, "text-anchor": "middle", class: "tick" }, String(k)),
      );
    }
    box.appendChild(
      svg("text", { x: x0 - 10, y: axisY + 15, "text-anchor": "end", class: "tick" }, "trial k"),
    );

    const r = Math.max(2.5, Math.min(6, step * 0.35));
    const showCost = step >= 30;
    for (const t of trials) {
      const i = rows.indexOf(t.strategy);
      if (i < 0) continue;
      const x = X(t.k);
      const y = top + i * rowH + rowH / 2;
      const colour = strategyColour(t.strategy);
      const status = t.status || "searching";
      const g = svg("g", {
        class: "mark" + (t.trial === S.watchedId ? " watched" : ""),
        "data-k": t.k,
        "data-trial": t.trial,
        "data-strategy": t.strategy,
        "data-status": status,
        "data-cost": t.cost_m == null ? null : t.cost_m,
      });
      if (t.trial === S.watchedId)
        g.appendChild(
          svg("circle", {
            cx: x,
            cy: y,
            r: r + 3.5,
            fill: "none",
            stroke: "#0f172a",
            "stroke-width": 1.5,
          }),
        );
      if (status === "done") {
        g.appendChild(svg("circle", { cx: x, cy: y, r, fill: colour }));
      } else if (status === "searching") {
        g.appendChild(
          svg("circle", {
            cx: x,
            cy: y,
            r: r - 0.75,
            fill: "#fff",
            stroke: colour,
            "stroke-width": 1.5,
          }),
        );
      } else {
        g.appendChild(
          svg("path", {
            d: `M${x - r},${y - r}L${x + r},${y + r}M${x - r},${y + r}L${x + r},${y - r}`,
            stroke: colour,
            "stroke-width": 2,
          }),
        );
      }
      if (showCost && t.cost_m != null && status !== "searching") {
        const above = t.trial === S.watchedId ? r + 5 : r + 2;
        g.appendChild(
          svg(
            "text",
            { x, y: y - above, "text-anchor": "middle", class: "cost" },
            t.cost_m.toFixed(1),
          ),
        );
      }
      // A generous, invisible target for the click.
      g.appendChild(
        svg("rect", {
          x: x - Math.max(step / 2, 4),
          y: y - rowH / 2,
          width: Math.max(step, 8),
          height: rowH,
          fill: "transparent",
        }),
      );
      titled(
        g,
        `trial ${t.trial} (k = ${t.k}): ${t.strategy}, looking for ${t.target}, ${status}` +
          (t.cost_m != null && status !== "searching" ? `, ${fmtM(t.cost_m)} m` : "") +
          "\nclick to watch it",
      );
      g.addEventListener("click", () => watch(t.trial, true));
      box.appendChild(g);
    }
  }

  // How long since a robot was heard from, in words, and whether it counts as silent.
  function heardWords(heardAt) {
    if (heardAt == null) return null;
    const s = Math.max(0, Math.round((Date.now() - heardAt) / 1000));
    const silent = s > SILENT_AFTER_S;
    return { silent, text: silent ? `silent for ${s} s` : `heard ${s} s ago` };
  }

  // The robots searching: each open trial with its robot (as it named itself), what it looks
  // for and how long since it was last heard from; one silent past SILENT_AFTER_S is marked.
  function drawOpenTrials() {
    const list = $("open-trials");
    list.replaceChildren();
    const dep = S.dep;
    if (!dep) return;
    const rows = new Map(dep.trials.map((t) => [t.trial, t]));
    for (const id of dep.open_trials) {
      const t = rows.get(id) || {};
      const ev = S.live.get(id);
      const watched = id === S.watchedId;
      const robot = t.robot || (ev && ev.robot) || null;
      const b = el("button", {
        type: "button",
        "data-trial": id,
        "aria-current": watched ? "true" : null,
        class: watched ? "watched" : "",
      });
      const parts = [
        `trial ${id}`,
        t.target || (ev && ev.target) || "?",
        t.strategy || (ev && ev.strategy) || "?",
      ];
      if (ev)
        parts.push(
          `${ev.searched} searched`,
          `${fmtM(ev.cost_m)} m`,
          ev.next ? `next ${S.scene && S.scene.name === ev.scene ? containerWords(ev.next) : ev.next}` : "",
        );
      b.append(
        el("span", { class: robot ? "robot" : "robot muted" }, robot || "unnamed robot"),
        document.createTextNode(
          " · " + parts.filter(Boolean).join(" · ") + (watched ? "  (watching)" : ""),
        ),
      );
      const heard = heardWords(t.heardAt);
      if (heard) {
        b.append(" · ", el("span", { class: "heard" }, heard.text));
        b.title = `silent: not heard from for more than ${SILENT_AFTER_S} s`;
      }
      b.addEventListener("click", () => watch(id, true));
      const li = el("li", {
        "data-trial": id,
        "data-robot": robot || "",
        "data-silent": heard ? String(heard.silent) : "",
      });
      li.appendChild(b);
      list.appendChild(li);
    }
    if (!dep.open_trials.length)
      list.appendChild(el("li", { class: "muted empty" }, "none: no robot is searching"));
  }

  // Ages change without events: the open trials' are redrawn every second.
  function tickAges() {
    const dep = S.dep;
    if (!dep || !dep.open_trials.length) return;
    const rows = new Map(dep.trials.map((t) => [t.trial, t]));
    for (const li of $("open-trials").querySelectorAll("li[data-trial]")) {
      const t = rows.get(Number(li.dataset.trial));
      const heard = t && heardWords(t.heardAt);
      const span = li.querySelector(".heard");
      if (!heard || !span) continue;
      span.textContent = heard.text;
      li.dataset.silent = String(heard.silent);
    }
  }

  // ---------------------------------------------------------------- giving a trial up

  // An operator may end a stuck robot's trial from the page (as the robot would with POST
  // /trials/{id}/abandon); a second click confirms it. A view-only server refuses, and says so.
  function renderAbandon(trial) {
    const box = $("abandon-box");
    const open = !!trial && trial.status === "searching";
    box.hidden = !open;
    if (!open || S.abandoning !== trial.trial) {
      S.abandoning = null;
      $("abandon").hidden = false;
      $("abandon-confirm").hidden = true;
    }
    if (!open) $("abandon-error").hidden = true;
  }

  async function abandonWatched() {
    const id = S.abandoning;
    if (id == null) return;
    const err = $("abandon-error");
    err.hidden = true;
    $("abandon-yes").disabled = true;
    try {
      const rid = `page-${Date.now().toString(36)}-${Math.random().toString(36).slice(2, 10)}`;
      await api(`/trials/${seg(id)}/abandon`, { request_id: rid });
      S.abandoning = null;
      if (id === S.watchedId) refetchView();
    } catch (e) {
      if (e instanceof Stale) return;
      err.textContent = `Not given up: ${e.message}`;
      err.hidden = false;
    } finally {
      $("abandon-yes").disabled = false;
    }
  }

  // ---------------------------------------------------------------- wiring

  function init() {
    $("token-form").addEventListener("submit", (ev) => {
      ev.preventDefault();
      S.token = $("token-input").value.trim();
      saveToken(S.token);
      $("token-input").value = "";
      start();
    });
    $("token-button").addEventListener("click", () => {
      const panel = $("token-panel");
      panel.hidden = !panel.hidden;
      if (!panel.hidden) $("token-input").focus();
    });
    $("deployment-select").addEventListener("change", (ev) => {
      const id = Number(ev.target.value);
      if (Number.isFinite(id)) {
        S.watchedId = null;
        S.view = null;
        selectDeployment(id, true);
      }
    });
    $("follow").addEventListener("click", () => {
      S.follow = true;
      S.watchedId = null;
      renderFollow();
      followNewest();
    });
    let resizeTimer = null;
    window.addEventListener("resize", () => {
      clearTimeout(resizeTimer);
      resizeTimer = setTimeout(() => {
        renderPlan();
        renderCurve();
      }, 150);
    });
    $("abandon").addEventListener("click", () => {
      if (S.watchedId == null) return;
      S.abandoning = S.watchedId;
      $("abandon-trial").textContent = String(S.watchedId);
      $("abandon").hidden = true;
      $("abandon-confirm").hidden = false;
      $("abandon-error").hidden = true;
    });
    $("abandon-no").addEventListener("click", () => {
      S.abandoning = null;
      $("abandon").hidden = false;
      $("abandon-confirm").hidden = true;
    });
    $("abandon-yes").addEventListener("click", abandonWatched);
    setInterval(tickAges, 1000);
    S.token = readToken();
    start();
  }

  if (document.readyState === "loading") document.addEventListener("DOMContentLoaded", init);
  else init();
})();
