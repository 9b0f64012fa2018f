//! Crowd simulation (§6): agents enter at their entry points and times, head for their goals with
//! the learnt action models, switch behaviour through the finite-state machine of §6.1 (groups
//! that form, accept members up to the data's mean group size and dissolve after the data's mean
//! duration; lines joined at the end and left at the front; behaviours assigned by region), and
//! leave at their goals. Output: `herdfit.tracks/1` rows with the behaviour as role.

use super::behaviour::{INTERACTION, LINE, LOCOMOTION};
use super::entries::{deadline, walking_groups};
pub use super::entries::{entries_from_layout, entries_from_tracks, typical_speed, Entry};
use super::features::{unit, V2};
use super::layout::Layout;
use super::model::{toward, CrowdModel};
pub use super::steer::steer_to_goals;
use super::steer::stop_at_places;
use super::step::{advance, plan, separate, Agent, Planned};
use crate::data::tracks::{TrackRow, Tracks, TracksMeta};
use crate::error::{Error, Result};
use crate::progress::Progress;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Settings of `crowd simulate`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Steps to simulate (0: until the last entry has had `timeout` × its expected walk, or the
    /// layout's duration).
    pub steps: usize,
    pub seed: u64,
    /// Agents within this distance (units) of their goal leave.
    pub arrive: f64,
    /// An agent still walking after `timeout` × (its straight-line distance / entry speed) leaves.
    pub timeout: f64,
    /// Run the behaviour machine (groups, lines); off: every agent uses locomotion.
    pub behaviours: bool,
    /// Spacing (units) of agents in a line.
    pub line_spacing: f64,
    /// Seconds the front of a line waits before leaving.
    pub line_service: f64,
    /// Hard minimum distance (units) between agents after each step ([`separate`]); 0: off.
    /// 0.3 m, fixed a priori: about the narrowest centre-to-centre spacing of two adults
    /// shoulder to shoulder.
    pub min_distance: f64,
    /// Goal steering (degrees): a walking agent with a goal takes its learnt step within this
    /// angle of the direction to the goal, its step turned to the edge of the cone when the model
    /// points farther away (the speed is kept); 180: off. The paper takes the direction to the
    /// goal as the intended moving direction in simulation (§4), but with Table 1's locomotion
    /// weights that feature barely moves the state, so on an unseen scene the learnt steps alone
    /// do not bring agents home. 60°, fixed a priori: at the edge of the cone an agent
    /// still closes on its goal at half its speed.
    pub goal_cone_deg: f64,
    /// Walking groups ([`walking_groups`]): entries that appear within `together_seconds` and
    /// `together` (units) of each other and are last seen as close in time and place walk together;
    /// each step its members draw their actions from one shared random stream, so that the same
    /// real steps are drawn for the same states. 0: off.
    pub together: f64,
    /// Seconds apart that group members may enter and leave ([`SimConfig::together`]).
    pub together_seconds: f64,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            steps: 0,
            seed: 0,
            arrive: 1.0,
            timeout: 3.0,
            behaviours: true,
            line_spacing: 0.8,
            line_service: 4.0,
            min_distance: 0.3,
            goal_cone_deg: 60.0,
            together: 1.0,
            together_seconds: 0.8,
        }
    }
}

/// Passes of the minimum-distance correction per step.
pub const SEPARATION_PASSES: usize = 3;

impl SimConfig {
    pub fn check(&self) -> Result<()> {
        for (v, k) in [
            (self.arrive, "arrive"),
            (self.timeout, "timeout"),
            (self.line_spacing, "line_spacing"),
            (self.line_service, "line_service"),
            (self.together_seconds, "together_seconds"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!("{k} = {v} must be > 0")));
            }
        }
        if !(self.goal_cone_deg.is_finite() && (0.0..=180.0).contains(&self.goal_cone_deg)) {
            return Err(Error::invalid(format!(
                "goal_cone = {} must be in 0..=180 degrees",
                crate::limits::show(self.goal_cone_deg)
            )));
        }
        // A distance in the tracks' unit: within the coordinate limit (issue #47).
        crate::limits::within(
            "min_distance",
            self.min_distance,
            0.0,
            crate::limits::MAX_COORD,
        )?;
        crate::limits::within("together", self.together, 0.0, crate::limits::MAX_COORD)?;
        crate::limits::within(
            "together_seconds",
            self.together_seconds,
            0.0,
            crate::limits::MAX_SECONDS,
        )?;
        Ok(())
    }
}

/// The steps a run takes (given, the layout's duration, or until the last entry is done), checked
/// against the limits before anything runs (issue #47: `--steps` and a layout's duration ran until
/// killed).
fn run_steps(
    layout: Option<&Layout>,
    entries: &[Entry],
    cfg: &SimConfig,
    dt: f64,
) -> Result<usize> {
    let steps = if cfg.steps > 0 {
        cfg.steps
    } else if let Some(d) = layout.and_then(|l| l.duration) {
        (d / dt).round().max(1.0) as usize
    } else {
        let last = entries
            .iter()
            .filter(|e| e.goal.is_some() || e.leave.is_some());
        let t = last.map(|e| deadline(e, cfg.timeout, dt)).max();
        t.ok_or_else(|| {
            Error::invalid("steps = 0 needs goals or a layout duration to know when to stop")
        })?
    };
    crate::limits::check_count("steps", steps, crate::limits::MAX_STEPS)?;
    crate::limits::check_memory(
        "steps",
        "the simulated tracks",
        entries.len() as f64 * steps as f64 * 96.0,
    )?;
    Ok(steps)
}

/// What a simulation produced.
pub struct SimResult {
    pub tracks: Tracks,
    /// Agent-steps simulated.
    pub agent_steps: u64,
    /// Agents that reached their goal / left by timeout.
    pub arrived: usize,
    pub timed_out: usize,
    /// Groups formed and agents that joined a line.
    pub groups_formed: usize,
    pub line_joins: usize,
    /// Walking groups among the entries ([`SimConfig::together`]) and the agents in them.
    pub walking_groups: (usize, usize),
}

/// Behaviour-machine state of one agent.
#[derive(Clone, Debug, Default)]
struct Mind {
    goal: Option<V2>,
    /// Step at which its interaction or line service ends.
    until: usize,
    /// No interaction before this step (after leaving a group).
    cooldown: usize,
    group: Option<usize>,
    /// Index of the line region it queues in, and whether it has been served.
    line: Option<usize>,
    served: bool,
    /// Lines it decided not to join (`join` < 1).
    declined: Vec<usize>,
    deadline: usize,
    /// It leaves at its deadline, not at its goal, grouped or queueing or not (an entry's
    /// `leave`).
    leaves_on_time: bool,
}

struct Machine<'a> {
    model: &'a CrowdModel,
    layout: Option<&'a Layout>,
    cfg: &'a SimConfig,
    inter: Option<usize>,
    groups: Vec<Vec<u64>>,
    /// Per line region: queue of agent ids, front first.
    lines: Vec<(usize, Vec<u64>)>,
    rng: ChaCha8Rng,
    groups_formed: usize,
    line_joins: usize,
}

fn exp_draw(rng: &mut ChaCha8Rng, mean: f64, dt: f64) -> usize {
    let u: f64 = rng.gen::<f64>().max(1e-12);
    ((-u.ln() * mean) / dt).ceil().max(1.0) as usize
}

impl Machine<'_> {
    /// Sets each agent's behaviour, goal and pivot for this step (§6.1).
    fn update(&mut self, t: usize, agents: &mut [Agent], minds: &mut [Mind]) {
        let loco = 0;
        let dt = self.model.dt;
        let fsm = &self.model.fsm;
        // Groups: members whose time is up leave; groups of one dissolve.
        for (a, m) in agents.iter_mut().zip(minds.iter_mut()) {
            if let Some(g) = m.group {
                if t >= m.until {
                    self.groups[g].retain(|&id| id != a.id);
                    m.group = None;
                    let loco_mean = fsm.mean_duration.get(LOCOMOTION).copied().unwrap_or(10.0);
                    m.cooldown = t + exp_draw(&mut self.rng, loco_mean, dt);
                }
            }
        }
        for (a, m) in agents.iter_mut().zip(minds.iter_mut()) {
            if let Some(g) = m.group {
                if self.groups[g].len() < 2 {
                    self.groups[g].clear();
                    m.group = None;
                    m.cooldown = t + 1;
                    let _ = a;
                }
            }
        }
        if let Some(ib) = self.inter.filter(|_| self.cfg.behaviours) {
            self.form_groups(t, agents, minds, ib);
        }
        if self.cfg.behaviours {
            self.queue_lines(t, agents, minds);
        }
        // Behaviour, goal and pivot from the machine state and the layout's regions.
        for (a, m) in agents.iter_mut().zip(minds.iter_mut()) {
            a.pivot = None;
            a.goal = m.goal;
            a.behaviour = loco;
            if m.group.is_some() {
                a.behaviour = self.inter.unwrap_or(loco);
                a.goal = None;
                continue;
            }
            if let Some(li) = m.line {
                let (ri, q) = &self.lines[li];
                let layout = self.layout.expect("lines come from a layout");
                let region = &layout.regions[*ri];
                let pv = layout
                    .pivot(region.pivot.as_deref().expect("checked"))
                    .expect("checked");
                let rank = q.iter().position(|&id| id == a.id).unwrap_or(0) as f64;
                let d = pv.pivot().dir();
                let slot = [
                    pv.position[0] - d[0] * self.cfg.line_spacing * rank,
                    pv.position[1] - d[1] * self.cfg.line_spacing * rank,
                ];
                a.goal = Some(slot);
                a.behaviour = self.model.behaviour(LINE).unwrap_or(loco);
                continue;
            }
            if let Some(r) = self.layout.and_then(|l| l.region_at(a.pos)) {
                if r.behaviour != LINE {
                    if let Some(b) = self.model.behaviour(&r.behaviour) {
                        a.behaviour = b;
                        a.pivot = r
                            .pivot
                            .as_deref()
                            .and_then(|n| self.layout.and_then(|l| l.pivot(n)))
                            .map(|p| p.pivot());
                    }
                }
            }
        }
    }

    /// Locomotion agents meeting within the interpersonal distance start or join a group.
    fn form_groups(&mut self, t: usize, agents: &[Agent], minds: &mut [Mind], _ib: usize) {
        let fsm = &self.model.fsm;
        let dt = self.model.dt;
        let reach = fsm.interpersonal * 1.5;
        let p_start = (fsm.start_rate * dt).clamp(0.0, 1.0);
        let inter_mean = fsm.mean_duration.get(INTERACTION).copied().unwrap_or(5.0);
        for i in 0..agents.len() {
            if minds[i].group.is_some() || minds[i].line.is_some() || t < minds[i].cooldown {
                continue;
            }
            let Some(j) = (0..agents.len()).find(|&j| {
                j != i
                    && minds[j].line.is_none()
                    && (agents[i].pos[0] - agents[j].pos[0])
                        .hypot(agents[i].pos[1] - agents[j].pos[1])
                        < reach
            }) else {
                continue;
            };
            if self.rng.gen::<f64>() >= p_start {
                continue;
            }
            match minds[j].group {
                Some(g) => {
                    let size = self.groups[g].len() as f64;
                    let accept = ((fsm.group_size - size) / fsm.group_size.max(1.0)).max(0.0);
                    if self.rng.gen::<f64>() < accept {
                        self.groups[g].push(agents[i].id);
                        minds[i].group = Some(g);
                        minds[i].until = t + exp_draw(&mut self.rng, inter_mean, dt);
                    }
                }
                None if t >= minds[j].cooldown => {
                    let g = self.groups.len();
                    self.groups.push(vec![agents[i].id, agents[j].id]);
                    self.groups_formed += 1;
                    for k in [i, j] {
                        minds[k].group = Some(g);
                        minds[k].until = t + exp_draw(&mut self.rng, inter_mean, dt);
                    }
                }
                None => {}
            }
        }
    }

    /// Agents entering a line region join its end; the front leaves after its service time.
    fn queue_lines(&mut self, t: usize, agents: &[Agent], minds: &mut [Mind]) {
        let Some(layout) = self.layout else { return };
        let dt = self.model.dt;
        for li in 0..self.lines.len() {
            let (ri, _) = self.lines[li];
            let front = self.lines[li].1.first().copied();
            if let Some(id) = front {
                if let Some(i) = agents.iter().position(|a| a.id == id) {
                    let pv = layout
                        .pivot(layout.regions[ri].pivot.as_deref().expect("checked"))
                        .expect("checked");
                    let at = (agents[i].pos[0] - pv.position[0])
                        .hypot(agents[i].pos[1] - pv.position[1])
                        < self.cfg.line_spacing;
                    if at && minds[i].until == 0 {
                        minds[i].until = t + exp_draw(&mut self.rng, self.cfg.line_service, dt);
                    }
                    if minds[i].until > 0 && t >= minds[i].until {
                        self.lines[li].1.remove(0);
                        minds[i].line = None;
                        minds[i].served = true;
                        minds[i].until = 0;
                    }
                } else {
                    self.lines[li].1.remove(0);
                }
            }
        }
        for (a, m) in agents.iter().zip(minds.iter_mut()) {
            if m.line.is_some() || m.served || m.group.is_some() {
                continue;
            }
            if let Some(li) = self
                .lines
                .iter()
                .position(|(ri, _)| super::layout::inside(&layout.regions[*ri].polygon, a.pos))
            {
                if m.declined.contains(&li) {
                    continue;
                }
                let join = layout.regions[self.lines[li].0].join;
                if join < 1.0 && self.rng.gen::<f64>() >= join {
                    m.declined.push(li);
                    continue;
                }
                self.lines[li].1.push(a.id);
                m.line = Some(li);
                m.until = 0;
                self.line_joins += 1;
            }
        }
    }
}

/// Simulates `entries` with `model` (in the layout's walls, obstacles and regions, if any).
pub fn simulate(
    model: &CrowdModel,
    layout: Option<&Layout>,
    entries: &[Entry],
    cfg: &SimConfig,
    progress: &mut dyn Progress,
) -> Result<SimResult> {
    cfg.check()?;
    if entries.is_empty() {
        return Err(Error::invalid(
            "no agents to simulate (no entries or spawns)",
        ));
    }
    let dt = model.dt;
    let steps = run_steps(layout, entries, cfg, dt)?;
    let segs = layout.map(|l| l.segments()).unwrap_or_default();
    let lines = layout
        .map(|l| {
            l.regions
                .iter()
                .enumerate()
                .filter(|(_, r)| r.behaviour == LINE)
                .map(|(i, _)| (i, Vec::new()))
                .collect()
        })
        .unwrap_or_default();
    let mut machine = Machine {
        model,
        layout,
        cfg,
        inter: model.behaviour(INTERACTION),
        groups: Vec::new(),
        lines,
        rng: ChaCha8Rng::seed_from_u64(cfg.seed ^ 0xf5a0_0f5a),
        groups_formed: 0,
        line_joins: 0,
    };
    let keep = model.config.features.intent_window + 2;
    let together = walking_groups(
        entries,
        cfg.together,
        (cfg.together_seconds / dt).round() as usize,
    );
    let (mut agents, mut minds): (Vec<Agent>, Vec<Mind>) = (Vec::new(), Vec::new());
    let mut rows = Vec::new();
    let mut roles: Vec<String> = Vec::new();
    let (mut next, mut agent_steps, mut arrived, mut timed_out) = (0, 0u64, 0, 0);
    progress.start("simulate", steps as u64);
    for t in 0..=steps {
        while next < entries.len() && entries[next].step <= t {
            let e = &entries[next];
            let h = unit(e.velocity).unwrap_or_else(|| toward(e.position, e.goal));
            let back = [
                e.position[0] - e.velocity[0] * dt,
                e.position[1] - e.velocity[1] * dt,
            ];
            let mut a = Agent::new(e.id, vec![back, e.position], h, e.goal, cfg.seed, dt);
            a.due = e.leave.map(|l| l.saturating_sub(t));
            a.group = together[next];
            agents.push(a);
            minds.push(Mind {
                goal: e.goal,
                deadline: deadline(e, cfg.timeout, dt).max(t + 1),
                leaves_on_time: e.leave.is_some(),
                ..Mind::default()
            });
            next += 1;
        }
        machine.update(t, &mut agents, &mut minds);
        roles.clear();
        roles.extend(agents.iter().zip(&minds).map(|(a, m)| {
            if m.line.is_some() {
                LINE.to_string()
            } else {
                model.behaviours[a.behaviour].name.clone()
            }
        }));
        let mut plans: Vec<Planned> = if agents.is_empty() {
            Vec::new()
        } else {
            plan(model, &mut agents)
        };
        // Near its goal an agent that leaves on time waits there as the model has it (standing
        // or milling about): turned back toward a goal it has overshot, it would zig-zag.
        let near = if entries.iter().any(|e| e.leave.is_some()) {
            cfg.arrive
        } else {
            0.0
        };
        steer_to_goals(
            &agents,
            &mut plans,
            cfg.goal_cone_deg,
            near,
            not_grouped(&minds),
        );
        if cfg.together > 0.0 {
            hold_groups(&mut agents, &mut plans);
        }
        stop_at_places(&agents, &mut plans, &in_line(&minds), dt);
        for ((a, p), role) in agents.iter().zip(&plans).zip(&roles) {
            rows.push(TrackRow {
                frame: t as u64,
                time: t as f64 * dt,
                id: a.id,
                pos: [a.pos[0], a.pos[1], 0.0],
                vel: Some([p.velocity[0], p.velocity[1], 0.0]),
                role: Some(role.clone()),
            });
        }
        if t == steps {
            break;
        }
        let walls = layout.map(|l| (l, segs.as_slice()));
        advance(model, &mut agents, &plans, walls, keep);
        separate(&mut agents, cfg.min_distance, SEPARATION_PASSES, walls);
        agent_steps += agents.len() as u64;
        let (home, late) = depart(t, &mut agents, &mut minds, &mut machine, cfg);
        arrived += home;
        timed_out += late;
        progress.inc(1);
    }
    progress.finish();
    let mut meta = TracksMeta::new(model.units, 1.0 / dt, 2);
    meta.provenance = serde_json::json!({
        "source": "herdfit crowd simulate",
        "config": cfg,
        "model_provenance": model.provenance,
    });
    Ok(SimResult {
        tracks: Tracks::new(meta, rows)?,
        agent_steps,
        arrived,
        timed_out,
        groups_formed: machine.groups_formed,
        line_joins: machine.line_joins,
        walking_groups: (
            together
                .iter()
                .zip(entries)
                .filter(|(g, e)| **g == Some(e.id))
                .count(),
            together.iter().flatten().count(),
        ),
    })
}

/// Removes the agents that leave after step `t`: at their goal (unless queueing, grouped or
/// leaving on time) or at their deadline. Returns (arrived, timed out).
fn depart(
    t: usize,
    agents: &mut Vec<Agent>,
    minds: &mut Vec<Mind>,
    machine: &mut Machine,
    cfg: &SimConfig,
) -> (usize, usize) {
    let (mut arrived, mut timed_out) = (0, 0);
    let mut i = 0;
    while i < agents.len() {
        let m = &minds[i];
        let free = m.group.is_none() && m.line.is_none();
        let at_goal = m
            .goal
            .is_some_and(|g| (agents[i].pos[0] - g[0]).hypot(agents[i].pos[1] - g[1]) < cfg.arrive);
        let home = at_goal && free && !m.leaves_on_time;
        let late = t + 1 >= m.deadline && (free || m.leaves_on_time);
        if !(home || late) {
            i += 1;
            continue;
        }
        if let Some(g) = m.group {
            machine.groups[g].retain(|&id| id != agents[i].id);
        }
        if let Some(li) = m.line {
            machine.lines[li].1.retain(|&id| id != agents[i].id);
        }
        if at_goal {
            arrived += 1;
        } else {
            timed_out += 1;
        }
        agents.remove(i);
        minds.remove(i);
    }
    (arrived, timed_out)
}

/// Per agent: whether goal steering applies (walking to its goal or to its place in a line;
/// not while in a group).
fn not_grouped(minds: &[Mind]) -> Vec<bool> {
    minds.iter().map(|m| m.group.is_none()).collect()
}

/// Per agent: whether it queues in a line.
fn in_line(minds: &[Mind]) -> Vec<bool> {
    minds.iter().map(|m| m.line.is_some()).collect()
}

/// Walking groups keep together: the first member to enter leads (its learnt step, steered to its
/// goal, as planned) and every other member present takes the leader's step, so each keeps the
/// place beside the leader it entered at. A member whose leader has left walks on its own.
fn hold_groups(agents: &mut [Agent], plans: &mut [Planned]) {
    let lead: HashMap<u64, usize> = agents
        .iter()
        .enumerate()
        .filter(|(_, a)| a.group == Some(a.id))
        .map(|(i, a)| (a.id, i))
        .collect();
    for (a, i) in agents.iter_mut().zip(0..) {
        let Some(g) = a.group.filter(|&g| g != a.id) else {
            continue;
        };
        match lead.get(&g) {
            Some(&l) => plans[i].velocity = plans[l].velocity,
            None => a.group = None,
        }
    }
}
