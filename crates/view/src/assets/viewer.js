// The Strata viewer: plain JavaScript, no build step. It asks the server for the state at a
// time (/api/frame?t=), draws the field on a canvas, and plots one robot's head-goal scores and
// ball confidence (/api/series). URL parameters: ?t=SECONDS (open paused at that time),
// &robot=home/2 (select a robot), &play=1 (start playing).
'use strict';

const TEAM_COLOURS = ['#42a5f5', '#ef5350'];
const PALETTE = ['#ffd54f', '#4dd0e1', '#ba68c8', '#81c784', '#ff8a65', '#f06292', '#aed581',
  '#90caf9', '#ffb74d', '#e57373', '#9575cd', '#4db6ac', '#fff176', '#a1887f'];

const ui = {
  canvas: document.getElementById('field'),
  robot: document.getElementById('robot'),
  details: document.getElementById('details'),
  play: document.getElementById('play'),
  timeline: document.getElementById('timeline'),
  time: document.getElementById('time'),
  speed: document.getElementById('speed'),
  live: document.getElementById('live'),
  window: document.getElementById('window'),
  source: document.getElementById('source'),
  game: document.getElementById('game'),
  warnings: document.getElementById('warnings'),
  drawn: document.getElementById('drawn'),
  goalLegend: document.getElementById('goal-legend'),
  plots: {
    final: document.getElementById('plot-final'),
    deliberative: document.getElementById('plot-deliberative'),
    reactive: document.getElementById('plot-reactive'),
    ball: document.getElementById('plot-ball'),
  },
};

const state = {
  info: null,
  frame: null,
  t: 0,
  playing: false,
  follow: false, // live: stay at the newest time
  selected: null,
  series: null,
  hiddenGoals: new Set(),
  shownGoals: null, // goals picked by default for the current robot
  frameInFlight: false,
  wantedT: null,
  lastTick: null,
  lastSeriesFetch: 0,
  seriesInFlight: false,
};

async function getJSON(url) {
  const response = await fetch(url, { cache: 'no-store' });
  if (!response.ok) {
    let detail = response.statusText;
    try { detail = (await response.json()).error || detail; } catch (_) { /* not JSON */ }
    throw new Error(`${url}: ${detail}`);
  }
  return response.json();
}

function colourOf(label) {
  let h = 0;
  for (const c of label) h = (h * 31 + c.charCodeAt(0)) >>> 0;
  return PALETTE[h % PALETTE.length];
}

// ---- Field geometry: field metres (x right, y up) to canvas pixels. ----

function fieldTransform(canvas, field) {
  const w = canvas.width, h = canvas.height;
  const spanX = field.length + 2 * field.border, spanY = field.width + 2 * field.border;
  const scale = Math.min(w / spanX, h / spanY);
  return {
    scale,
    px: (x) => w / 2 + x * scale,
    py: (y) => h / 2 - y * scale,
  };
}

function fitCanvas(canvas) {
  const rect = canvas.getBoundingClientRect();
  const ratio = window.devicePixelRatio || 1;
  const w = Math.max(200, Math.round(rect.width * ratio));
  const h = Math.max(120, Math.round(rect.height * ratio));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
}

function drawField(ctx, f, field) {
  ctx.fillStyle = '#2e7d32';
  ctx.fillRect(0, 0, ctx.canvas.width, ctx.canvas.height);
  ctx.strokeStyle = '#f5f5f5';
  ctx.lineWidth = Math.max(1, field.line_width * f.scale);
  for (const [x0, y0, x1, y1] of field.lines) {
    ctx.beginPath();
    ctx.moveTo(f.px(x0), f.py(y0));
    ctx.lineTo(f.px(x1), f.py(y1));
    ctx.stroke();
  }
  const [cx, cy, r] = field.centre_circle;
  ctx.beginPath();
  ctx.arc(f.px(cx), f.py(cy), r * f.scale, 0, 2 * Math.PI);
  ctx.stroke();
  ctx.fillStyle = '#f5f5f5';
  for (const [x, y] of field.marks) {
    ctx.fillRect(f.px(x) - 2, f.py(y) - 2, 4, 4);
  }
  ctx.fillStyle = 'rgba(255, 255, 255, 0.12)';
  for (const [x0, y0, x1, y1] of field.goals) {
    ctx.fillRect(f.px(Math.min(x0, x1)), f.py(Math.max(y0, y1)),
      Math.abs(x1 - x0) * f.scale, Math.abs(y1 - y0) * f.scale);
  }
  ctx.fillStyle = '#ffffff';
  for (const [x, y] of field.posts) {
    ctx.beginPath();
    ctx.arc(f.px(x), f.py(y), Math.max(3, field.post_diameter * f.scale / 2), 0, 2 * Math.PI);
    ctx.fill();
  }
  for (const b of field.beacons) {
    const colours = b.colours.length ? b.colours : ['white'];
    colours.forEach((c, i) => {
      ctx.fillStyle = c;
      ctx.beginPath();
      ctx.arc(f.px(b.x), f.py(b.y), 9 - i * 3, 0, 2 * Math.PI);
      ctx.fill();
    });
  }
}

function drawRobot(ctx, f, info, robot, selected, drawn) {
  const colour = robot.penalty && robot.penalty !== 'none' ? '#9e9e9e' : TEAM_COLOURS[robot.team];
  const radius = Math.max(6, 0.15 * f.scale);
  const record = { name: robot.name, team: robot.team };
  if (robot.pose && robot.present) {
    const p = robot.pose;
    const x = f.px(p.x), y = f.py(p.y);
    // Camera field of view: the head's direction in the field, +- half the FOV (canvas angles
    // run clockwise, field angles counter-clockwise).
    const gazeDir = p.theta + robot.head_yaw;
    const range = Math.min(info.camera_range, 3.5) * f.scale;
    ctx.fillStyle = selected ? 'rgba(255, 255, 255, 0.22)' : 'rgba(255, 255, 255, 0.10)';
    ctx.beginPath();
    ctx.moveTo(x, y);
    ctx.arc(x, y, range, -gazeDir - info.camera_fov / 2, -gazeDir + info.camera_fov / 2);
    ctx.closePath();
    ctx.fill();
    // Gaze target: where the selected head goal's objects are estimated.
    ctx.save();
    ctx.setLineDash([3, 4]);
    ctx.strokeStyle = selected ? '#ffffff' : 'rgba(255, 255, 255, 0.5)';
    ctx.lineWidth = selected ? 2 : 1;
    for (const g of robot.gaze) {
      ctx.beginPath();
      ctx.moveTo(x, y);
      ctx.lineTo(f.px(g.x), f.py(g.y));
      ctx.stroke();
      ctx.strokeRect(f.px(g.x) - 4, f.py(g.y) - 4, 8, 8);
    }
    ctx.restore();
    // Body and heading.
    ctx.fillStyle = colour;
    ctx.strokeStyle = selected ? '#ffffff' : '#111';
    ctx.lineWidth = selected ? 3 : 1.5;
    ctx.beginPath();
    ctx.arc(x, y, radius, 0, 2 * Math.PI);
    ctx.fill();
    ctx.stroke();
    ctx.strokeStyle = '#111';
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(x, y);
    ctx.lineTo(x + Math.cos(p.theta) * radius * 1.6, y - Math.sin(p.theta) * radius * 1.6);
    ctx.stroke();
    if (robot.fallen) {
      ctx.strokeStyle = '#fff';
      ctx.beginPath();
      ctx.moveTo(x - radius, y - radius); ctx.lineTo(x + radius, y + radius);
      ctx.moveTo(x + radius, y - radius); ctx.lineTo(x - radius, y + radius);
      ctx.stroke();
    }
    // Label: player, role and mission.
    ctx.fillStyle = '#fff';
    ctx.font = `${Math.max(11, Math.round(radius * 0.9))}px system-ui, sans-serif`;
    ctx.textAlign = 'center';
    const role = robot.role ? ` ${robot.role}` : '';
    const mission = robot.mission ? ` (${robot.mission})` : '';
    ctx.fillText(`${robot.player}${role}${mission}`, x, y - radius - 6);
    record.x = p.x; record.y = p.y; record.theta = p.theta; record.px = x; record.py = y;
  }
  if (robot.estimate) {
    const e = robot.estimate;
    const x = f.px(e.x), y = f.py(e.y);
    ctx.save();
    ctx.setLineDash([4, 3]);
    ctx.strokeStyle = colour;
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.arc(x, y, radius, 0, 2 * Math.PI);
    ctx.moveTo(x, y);
    ctx.lineTo(x + Math.cos(e.theta) * radius * 1.6, y - Math.sin(e.theta) * radius * 1.6);
    ctx.stroke();
    ctx.restore();
    if (robot.pose && robot.present) {
      ctx.strokeStyle = 'rgba(255, 255, 255, 0.35)';
      ctx.lineWidth = 1;
      ctx.beginPath();
      ctx.moveTo(f.px(robot.pose.x), f.py(robot.pose.y));
      ctx.lineTo(x, y);
      ctx.stroke();
    }
    record.estimate = { x: e.x, y: e.y, theta: e.theta, px: x, py: y };
  }
  if (robot.ball) {
    const b = robot.ball;
    ctx.strokeStyle = colour;
    ctx.globalAlpha = 0.25 + 0.75 * Math.max(0, Math.min(1, b.confidence));
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.arc(f.px(b.x), f.py(b.y), Math.max(5, 0.06 * f.scale), 0, 2 * Math.PI);
    ctx.stroke();
    // The estimate's 2-sigma covariance ellipse, the scene's (Foxglove draws the same).
    if (b.ellipse && b.ellipse.length > 2) {
      ctx.lineWidth = 1;
      ctx.setLineDash([4, 3]);
      ctx.beginPath();
      b.ellipse.forEach(([ex, ey], i) => {
        if (i === 0) ctx.moveTo(f.px(ex), f.py(ey)); else ctx.lineTo(f.px(ex), f.py(ey));
      });
      ctx.closePath();
      ctx.stroke();
      ctx.setLineDash([]);
    }
    ctx.globalAlpha = 1;
    record.ball = { x: b.x, y: b.y, px: f.px(b.x), py: f.py(b.y) };
  }
  if (robot.team_ball) {
    const b = robot.team_ball;
    const s = Math.max(4, 0.05 * f.scale);
    ctx.fillStyle = colour;
    ctx.strokeStyle = '#ffd54f';
    ctx.beginPath();
    ctx.moveTo(f.px(b.x), f.py(b.y) - s);
    ctx.lineTo(f.px(b.x) + s, f.py(b.y));
    ctx.lineTo(f.px(b.x), f.py(b.y) + s);
    ctx.lineTo(f.px(b.x) - s, f.py(b.y));
    ctx.closePath();
    ctx.fill();
    ctx.stroke();
    record.team_ball = { x: b.x, y: b.y };
  }
  drawn.robots.push(record);
}

function drawFrame() {
  const { info, frame } = state;
  if (!info || !frame) return;
  const canvas = ui.canvas;
  fitCanvas(canvas);
  const ctx = canvas.getContext('2d');
  const f = fieldTransform(canvas, info.field);
  drawField(ctx, f, info.field);
  const drawn = { t: frame.t, truth_t: frame.truth_t, canvas: { width: canvas.width, height: canvas.height },
    scale: f.scale, ball: null, robots: [] };
  // The selected robot last, on top.
  const robots = [...frame.robots].sort((a, b) => (a.name === state.selected) - (b.name === state.selected));
  for (const robot of robots) drawRobot(ctx, f, info, robot, robot.name === state.selected, drawn);
  if (frame.ball) {
    const x = f.px(frame.ball.x), y = f.py(frame.ball.y);
    ctx.fillStyle = '#ff9800';
    ctx.strokeStyle = '#111';
    ctx.lineWidth = 1.5;
    ctx.beginPath();
    ctx.arc(x, y, Math.max(5, 0.05 * f.scale), 0, 2 * Math.PI);
    ctx.fill();
    ctx.stroke();
    drawn.ball = { x: frame.ball.x, y: frame.ball.y, px: x, py: y };
  }
  drawn.robots.sort((a, b) => a.name.localeCompare(b.name));
  window.__drawn = drawn;
  ui.drawn.textContent = JSON.stringify(drawn);
  document.body.dataset.t = String(frame.t);
  drawHeader();
  drawDetails();
  drawPlots();
}

function fmtClock(secs) {
  const s = Math.max(0, Math.round(secs));
  return `${Math.floor(s / 60)}:${String(s % 60).padStart(2, '0')}`;
}

function drawHeader() {
  const { info, frame } = state;
  const g = frame.game;
  ui.game.textContent = g
    ? `${info.teams[0]} ${g.score[0]} - ${g.score[1]} ${info.teams[1]}   ${g.state}` +
      `${g.set_play && g.set_play !== 'none' ? ' (' + g.set_play + ')' : ''}   ` +
      `${g.first_half ? '1st' : '2nd'} half ${fmtClock(g.secs_remaining)}`
    : '';
  ui.time.textContent = `${frame.t.toFixed(2)} s`;
  if (!state.scrubbing) ui.timeline.value = String(frame.t);
}

function drawDetails() {
  const robot = state.frame.robots.find((r) => r.name === state.selected);
  const rows = [];
  if (robot) {
    const num = (v, d = 2) => (v === null || v === undefined ? '–' : Number(v).toFixed(d));
    const pose = (p) => (p ? `${num(p.x)}, ${num(p.y)}, ${num(p.theta * 180 / Math.PI, 0)}°` : '–');
    rows.push(['mission / role', `${robot.mission || '–'} / ${robot.role || '–'}`]);
    rows.push(['planning', robot.planning_path || '–']);
    rows.push(['deliberative', robot.deliberative_path || '–']);
    rows.push(['reactive', robot.reactive_path || '–']);
    rows.push(['head goal', robot.head_goal || '–']);
    rows.push(['true pose', pose(robot.pose)]);
    rows.push(['estimated pose', `${pose(robot.estimate)}  (confidence ${num(robot.pose_confidence)}${robot.lost ? ', lost' : ''})`]);
    rows.push(['ball estimate', robot.ball ? `${num(robot.ball.x)}, ${num(robot.ball.y)} (confidence ${num(robot.ball.confidence)}${robot.ball.known ? '' : ', unknown'})` : '–']);
    rows.push(['team ball', robot.team_ball ? `${num(robot.team_ball.x)}, ${num(robot.team_ball.y)}` : '–']);
    if (robot.penalty && robot.penalty !== 'none') rows.push(['penalty', robot.penalty]);
  }
  ui.details.replaceChildren(...rows.map(([k, v]) => {
    const tr = document.createElement('tr');
    const a = document.createElement('td'); a.textContent = k;
    const b = document.createElement('td'); b.textContent = v;
    tr.append(a, b);
    return tr;
  }));
}

// ---- Plots ----

function plotAxes(canvas, from, to, lo, hi) {
  fitCanvas(canvas);
  const ctx = canvas.getContext('2d');
  const w = canvas.width, h = canvas.height;
  const pad = { l: 30, r: 6, t: 14, b: 14 };
  ctx.fillStyle = '#15181c';
  ctx.fillRect(0, 0, w, h);
  ctx.fillStyle = '#999';
  ctx.font = '11px system-ui, sans-serif';
  ctx.textAlign = 'left';
  ctx.fillText(canvas.dataset.title, pad.l, 11);
  ctx.textAlign = 'right';
  ctx.fillText(hi.toFixed(1), pad.l - 3, pad.t + 4);
  ctx.fillText(lo.toFixed(1), pad.l - 3, h - pad.b);
  ctx.textAlign = 'center';
  ctx.fillText(`${from.toFixed(0)} s`, pad.l + 12, h - 2);
  ctx.fillText(`${to.toFixed(0)} s`, w - pad.r - 14, h - 2);
  const x = (t) => pad.l + (to > from ? (t - from) / (to - from) : 0) * (w - pad.l - pad.r);
  const y = (v) => h - pad.b - ((v - lo) / (hi - lo || 1)) * (h - pad.t - pad.b);
  ctx.strokeStyle = '#333';
  ctx.strokeRect(pad.l, pad.t, w - pad.l - pad.r, h - pad.t - pad.b);
  return { ctx, x, y };
}

function plotLine(p, ts, vs, colour) {
  const { ctx, x, y } = p;
  ctx.strokeStyle = colour;
  ctx.lineWidth = 1.5;
  ctx.beginPath();
  let pen = false;
  for (let i = 0; i < ts.length; i++) {
    const v = vs[i];
    if (v === null || v === undefined) { pen = false; continue; }
    if (pen) ctx.lineTo(x(ts[i]), y(v)); else ctx.moveTo(x(ts[i]), y(v));
    pen = true;
  }
  ctx.stroke();
}

function plotCursor(p, t, h) {
  p.ctx.strokeStyle = 'rgba(255, 255, 255, 0.6)';
  p.ctx.beginPath();
  p.ctx.moveTo(p.x(t), 0);
  p.ctx.lineTo(p.x(t), h);
  p.ctx.stroke();
}

function visibleGoals() {
  const s = state.series;
  if (!s) return [];
  if (!state.shownGoals) {
    // The goals that mattered most in the window: the highest final scores.
    const best = s.goals.map((g) => [g.goal, Math.max(...g.final.filter((v) => v !== null), 0)])
      .sort((a, b) => b[1] - a[1]).slice(0, 5).map(([goal]) => goal);
    state.shownGoals = new Set(best);
  }
  return s.goals.filter((g) => state.shownGoals.has(g.goal) && !state.hiddenGoals.has(g.goal));
}

function drawPlots() {
  const s = state.series;
  const t = state.frame ? state.frame.t : 0;
  const [from, to] = seriesWindow(t);
  const goals = visibleGoals();
  for (const key of ['final', 'deliberative', 'reactive']) {
    const canvas = ui.plots[key];
    const p = plotAxes(canvas, from, to, 0, 1);
    for (const g of goals) plotLine(p, g.t, g[key], colourOf(g.goal));
    plotCursor(p, t, canvas.height);
  }
  const ball = plotAxes(ui.plots.ball, from, to, 0, 1);
  if (s) plotLine(ball, s.ball_confidence.map((v) => v[0]), s.ball_confidence.map((v) => v[1]), '#ff9800');
  plotCursor(ball, t, ui.plots.ball.height);
  if (s) {
    const spans = s.goals.map((g) => {
      const span = document.createElement('span');
      const on = state.shownGoals && state.shownGoals.has(g.goal) && !state.hiddenGoals.has(g.goal);
      span.className = on ? '' : 'off';
      const swatch = document.createElement('i');
      swatch.style.background = colourOf(g.goal);
      span.append(swatch, g.goal);
      span.onclick = () => {
        if (on) state.hiddenGoals.add(g.goal);
        else { state.hiddenGoals.delete(g.goal); state.shownGoals.add(g.goal); }
        drawPlots();
      };
      return span;
    });
    ui.goalLegend.replaceChildren(...spans);
  }
}

function seriesWindow(t) {
  const w = Number(ui.window.value);
  const info = state.info;
  if (!w || !info) return [info ? info.start : 0, info ? Math.max(info.end, t) : t];
  if (state.follow) return [Math.max(info.start, t - w), t];
  // Around the cursor, kept inside the run.
  const from = Math.max(info.start, Math.min(t - w / 2, info.end - w));
  return [from, from + w];
}

async function loadSeries() {
  if (!state.selected || state.seriesInFlight) return;
  state.seriesInFlight = true;
  const t = state.frame ? state.frame.t : state.t;
  const [from, to] = seriesWindow(t);
  try {
    const robot = encodeURIComponent(state.selected);
    state.series = await getJSON(`/api/series?robot=${robot}&from=${from}&to=${to}&points=600`);
    state.lastSeriesFetch = performance.now();
  } catch (e) {
    showError(e);
  } finally {
    state.seriesInFlight = false;
  }
  drawPlots();
}

// ---- Time ----

function showError(e) {
  ui.warnings.textContent = String(e.message || e);
}

async function loadFrame(t) {
  if (state.frameInFlight) { state.wantedT = t; return; }
  state.frameInFlight = true;
  try {
    const url = t === null ? '/api/frame' : `/api/frame?t=${t.toFixed(3)}`;
    state.frame = await getJSON(url);
    state.t = state.frame.t;
    drawFrame();
  } catch (e) {
    showError(e);
  } finally {
    state.frameInFlight = false;
  }
  if (state.wantedT !== null) {
    const next = state.wantedT;
    state.wantedT = null;
    await loadFrame(next);
  }
}

async function refreshInfo() {
  const info = await getJSON('/api/info');
  state.info = info;
  ui.timeline.min = String(info.start);
  ui.timeline.max = String(Math.max(info.end, info.start));
  ui.live.hidden = !(info.source === 'live' && info.growing);
  ui.source.textContent = info.source === 'live'
    ? `live match${info.growing ? '' : ' (over)'}${info.seed !== null ? ', seed ' + info.seed : ''}`
    : `${info.file}${info.growing ? ' (reading…)' : ''}${info.seed !== null ? ', seed ' + info.seed : ''}`;
  if (info.warnings.length) ui.warnings.textContent = info.warnings.join('; ');
  const names = info.robots;
  if (names.length !== ui.robot.options.length) {
    ui.robot.replaceChildren(...names.map((n) => new Option(n, n)));
  }
  if (!state.selected || !names.includes(state.selected)) state.selected = names[0] || null;
  if (state.selected) ui.robot.value = state.selected;
  return info;
}

function setPlaying(playing) {
  state.playing = playing;
  state.lastTick = null;
  ui.play.textContent = playing ? 'Pause' : 'Play';
}

function tick(now) {
  const info = state.info;
  if (state.playing && info) {
    if (state.lastTick !== null) {
      const dt = (now - state.lastTick) / 1000 * Number(ui.speed.value);
      const t = Math.min(state.t + dt, info.end);
      state.t = t;
      if (t >= info.end && !info.growing) setPlaying(false);
      loadFrame(t);
    }
    state.lastTick = now;
  }
  if ((state.playing || state.follow) && now - state.lastSeriesFetch > 1000) loadSeries();
  requestAnimationFrame(tick);
}

async function pollLive() {
  if (!state.info || !state.info.growing) return;
  try {
    await refreshInfo();
    if (state.follow) await loadFrame(null);
  } catch (e) {
    showError(e);
  }
}

async function main() {
  const params = new URLSearchParams(location.search);
  try {
    await refreshInfo();
  } catch (e) {
    showError(e);
    return;
  }
  const info = state.info;
  if (params.has('robot')) {
    state.selected = params.get('robot');
    ui.robot.value = state.selected;
  }
  const asked = params.has('t') ? Number(params.get('t')) : null;
  if (asked !== null && Number.isFinite(asked)) {
    await loadFrame(asked);
  } else if (info.source === 'live' && info.growing) {
    state.follow = true;
    await loadFrame(null);
  } else {
    await loadFrame(info.start);
  }
  await loadSeries();
  document.body.dataset.ready = '1';

  ui.play.onclick = () => { state.follow = false; setPlaying(!state.playing); };
  ui.timeline.oninput = () => {
    state.scrubbing = true;
    state.follow = false;
    state.t = Number(ui.timeline.value);
    loadFrame(state.t).then(loadSeries);
  };
  ui.timeline.onchange = () => { state.scrubbing = false; };
  ui.live.onclick = () => { state.follow = true; setPlaying(false); loadFrame(null); };
  ui.robot.onchange = () => {
    state.selected = ui.robot.value;
    state.shownGoals = null;
    state.hiddenGoals.clear();
    drawFrame();
    loadSeries();
  };
  ui.window.onchange = () => { state.shownGoals = null; loadSeries(); };
  window.addEventListener('resize', drawFrame);
  if (params.get('play') === '1') setPlaying(true);
  setInterval(pollLive, 200);
  requestAnimationFrame(tick);
}

main();
