//! Teams: 1 to [`MAX_ROBOTS`] robots in one house on one task. Each robot drives its own
//! [`Search`] (from its own start, on its own [`SearchProblem`]); a container one robot opens is
//! known to all at once; robots move at equal speeds, so metres are time. The trial ends when
//! the task's goal holds (with a destination: when the last robot carrying a target arrives
//! there). [`run_team`] is that simulator, and with one robot it is [`run_trial`]'s search step
//! for step, float for float.
//!
//! How robots share the work is the strategy's [`Teamwork`]: coordinated (a robot plans knowing
//! the containers the others are heading to), independent (each runs the single-robot plan on
//! what the team saw) or split by region (the rooms divided among them).
//!
//! [`run_trial`]: crate::run_trial

use ferret_world::grid::{Cell, CellKind};
use ferret_world::{Distances, GroundTruth, House, OccupancyGrid, Place, Point};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::belief::Belief;
use crate::error::PlanError;
use crate::policy::OracleTable;
use crate::problem::SearchProblem;
use crate::strategy::{Strategy, Teamwork};
use crate::task::{DestinationLegs, Goal, Task, TaskError};
use crate::trial::{Search, TrialOutcome, contents_of};

/// The most robots a team has.
pub const MAX_ROBOTS: usize = 4;

/// Where the robots of a team start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TeamStarts {
    /// Every robot at the house's start.
    #[default]
    Together,
    /// The first robot at the house's start, the others on reachable cells of the floor drawn
    /// uniformly by a generator of the house and the seed.
    Spread,
}

impl std::str::FromStr for TeamStarts {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "together" | "start" => Ok(Self::Together),
            "spread" => Ok(Self::Spread),
            other => Err(format!("`{other}`: expected `together` or `spread`")),
        }
    }
}

impl std::fmt::Display for TeamStarts {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Together => "together",
            Self::Spread => "spread",
        })
    }
}

/// A team: how many robots, and where they start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TeamSettings {
    /// Robots, 1 to [`MAX_ROBOTS`].
    pub robots: usize,
    /// Where they start.
    #[serde(default)]
    pub starts: TeamStarts,
}

impl TeamSettings {
    /// `robots` robots starting as `starts` says.
    ///
    /// # Errors
    /// A sentence, for no robots or more than [`MAX_ROBOTS`].
    pub fn new(robots: usize, starts: TeamStarts) -> Result<Self, String> {
        if !(1..=MAX_ROBOTS).contains(&robots) {
            return Err(format!("{robots} robots: a team has 1 to {MAX_ROBOTS}"));
        }
        Ok(Self { robots, starts })
    }
}

/// The cells the robots of a team start on: the grid's start cell for the first and, spread,
/// reachable cells drawn for the others (stream of its own of the house and `seed`, so no other
/// draw moves).
pub fn draw_starts(
    house: &House,
    grid: &OccupancyGrid,
    robots: usize,
    starts: TeamStarts,
    seed: u64,
) -> Vec<Cell> {
    let first = grid.start_cell();
    if starts == TeamStarts::Together {
        return vec![first; robots];
    }
    let reachable: Vec<Cell> = grid
        .cells()
        .filter(|&(c, k)| k == CellKind::Free && grid.is_reachable(c))
        .map(|(c, _)| c)
        .collect();
    let mut rng =
        ChaCha8Rng::seed_from_u64(seed ^ (house.index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.set_stream(6);
    std::iter::once(first)
        .chain((1..robots).map(|_| {
            if reachable.is_empty() {
                first
            } else {
                reachable[rng.random_range(0..reachable.len())]
            }
        }))
        .collect()
}

/// The distances of each robot of a team: `distances` (measured from the house's start on
/// `grid`) for a robot at the grid's start cell, the same with the start moved for the others
/// (one grid search each; see [`Distances::with_start`]).
///
/// # Errors
/// [`PlanError::Team`] for a start the house's start cannot reach, or distances that came
/// from no grid.
pub fn team_distances(
    house: &House,
    grid: &OccupancyGrid,
    distances: &Distances,
    starts: &[Cell],
) -> Result<Vec<Distances>, PlanError> {
    let err = |message: String| PlanError::Team {
        house: house.name.clone(),
        message,
    };
    starts
        .iter()
        .enumerate()
        .map(|(r, &cell)| {
            if cell == grid.start_cell() {
                return Ok(distances.clone());
            }
            let at = grid.center(cell);
            let moved = grid
                .with_start(&house.name, at)
                .map_err(|e| err(format!("robot {r}: {e}")))?
                .ok_or_else(|| {
                    err(format!(
                        "robot {r}: ({:.2}, {:.2}) cannot be reached from the house's start",
                        at.x, at.z
                    ))
                })?;
            distances
                .with_start(house, &moved)
                .map_err(|e| err(format!("robot {r}: {e}")))
        })
        .collect()
}

/// The task's destination for each robot of a team, on its own distances. `start` is the
/// house's start (where the person who asked is), which for a robot starting elsewhere is a
/// spot of its floor; `grid_start` is that cell.
///
/// # Errors
/// What [`Destination::legs`](crate::Destination::legs) refuses, on field `destination`.
pub fn team_destinations(
    house: &House,
    task: &Task,
    distances: &[Distances],
    grid_start: Cell,
    starts: &[Cell],
) -> Result<Vec<Option<DestinationLegs>>, TaskError> {
    let Some(d) = task.destination() else {
        return Ok(vec![None; distances.len()]);
    };
    distances
        .iter()
        .zip(starts)
        .map(|(dist, &cell)| {
            if *d == crate::task::Destination::Start && cell != grid_start {
                let spot = dist
                    .spot(house, grid_start)
                    .map_err(|e| TaskError::new("destination", e.to_string()))?;
                Ok(Some(DestinationLegs::to_spot(dist, spot)))
            } else {
                d.legs(house, dist).map(Some)
            }
        })
        .collect()
}

/// What one robot of a team did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RobotRun {
    /// The containers it searched, in order.
    pub searched: Vec<usize>,
    /// Metres it drove until the trial ended (a leg under way counted as far as it got;
    /// the way to the destination included).
    pub travelled: f64,
    /// The container it was on its way to when the trial ended, if any, and when it would
    /// have got there (metres from the trial's start).
    pub heading: Option<(usize, f64)>,
    /// Whether it drove to the destination at the end.
    pub delivered: bool,
}

/// What happened in a team's trial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TeamOutcome {
    /// The trial as one outcome: `cost` is the makespan (metres until the goal held and, with a
    /// destination, the last carrier stood there), `searched` every container searched in the
    /// order they were, `delivery` the last leg to the destination of the robot that got there last.
    pub trial: TrialOutcome,
    /// Per robot, in team order.
    pub robots: Vec<RobotRun>,
    /// Which robot searched each container of `trial.searched`.
    pub searched_by: Vec<usize>,
    /// Metres driven by the whole team.
    pub total_travel: f64,
}

/// How one robot is steered.
enum Steer {
    /// By its strategy's policy, through its search.
    Plan,
    /// Along a route the oracle gave it; idle once it is done.
    Route(Vec<usize>),
}

struct Member<'a> {
    search: Search<'a>,
    steer: Steer,
    /// The container it is heading to, and when it gets there.
    claim: Option<(usize, f64)>,
    /// When it set off on its current leg.
    departed: f64,
    /// Since when it has had nothing left to search (it waits where it is, or, carrying a
    /// target, drives on to the destination at once).
    idle: Option<f64>,
    searched: Vec<usize>,
}

/// Runs `strategy` with one robot per problem (each robot's own start and distances; the same
/// house and trial) until the task's goal holds or nothing is left, then brings what was found
/// to the destination. Robots choose in index order when free at the same time; the robot that
/// arrives first searches first (ties to the lower index).
///
/// # Errors
/// [`PlanError::Team`] for no robots, more than [`MAX_ROBOTS`] or problems of different trials;
/// the strategy's own failures.
pub fn run_team(
    strategy: &dyn Strategy,
    problems: &[SearchProblem<'_>],
    truth: &GroundTruth,
) -> Result<TeamOutcome, PlanError> {
    let first = problems.first().ok_or_else(|| PlanError::Team {
        house: String::new(),
        message: "a team needs at least one robot".into(),
    })?;
    let house = first.house;
    let team_err = |message: String| PlanError::Team {
        house: house.name.clone(),
        message,
    };
    if problems.len() > MAX_ROBOTS {
        return Err(team_err(format!(
            "{} robots: a team has 1 to {MAX_ROBOTS}",
            problems.len()
        )));
    }
    // The same house may come placed at each robot's start (a service places a scene once
    // per pose): same name and containers, one trial.
    let same_house = |h: &House| {
        std::ptr::eq(h, house)
            || (h.name == house.name && h.containers.len() == house.containers.len())
    };
    if problems
        .iter()
        .any(|p| !same_house(p.house) || p.trial != first.trial)
    {
        return Err(team_err(
            "every robot of a team works on the same house and trial".into(),
        ));
    }
    let n = problems.len();
    let teamwork = strategy.teamwork();
    let routes = if strategy.needs_ground_truth() && n > 1 {
        Some(team_oracle_routes(problems, truth)?)
    } else {
        None
    };
    let mut members = Vec::with_capacity(n);
    for (r, p) in problems.iter().enumerate() {
        members.push(Member {
            search: Search::start(strategy, p, Some(truth))?,
            steer: match &routes {
                Some(routes) => Steer::Route(routes.get(r).cloned().unwrap_or_default()),
                None => Steer::Plan,
            },
            claim: None,
            departed: 0.0,
            idle: None,
            searched: Vec::new(),
        });
    }
    let regions = (teamwork == Teamwork::SplitByRegion && n > 1).then(|| {
        let starts: Vec<Point> = problems
            .iter()
            .map(|p| {
                p.distances
                    .point(Place::Start)
                    .unwrap_or(house.start.position)
            })
            .collect();
        split_rooms(house, &starts)
    });
    let mut now = 0.0_f64;
    let mut order: Vec<(usize, usize)> = Vec::new();
    let mut finder: Vec<Option<usize>> = vec![None; first.task().targets().len()];
    loop {
        for r in 0..n {
            if members[r].claim.is_some() || members[r].idle.is_some() {
                continue;
            }
            let next = match &members[r].steer {
                Steer::Route(route) => {
                    let b = members[r].search.belief();
                    let claimed =
                        |c: usize| members.iter().any(|m| m.claim.is_some_and(|x| x.0 == c));
                    if b.goal_holds() {
                        None
                    } else {
                        route
                            .iter()
                            .copied()
                            .find(|&c| !b.is_searched(c) && !claimed(c))
                    }
                }
                Steer::Plan => {
                    let others = leaving(&members, r, now, teamwork, regions.as_deref());
                    members[r].search.next_container_leaving(&others)?
                }
            };
            let m = &mut members[r];
            match next {
                Some(c) => {
                    let leg = m.search.belief().distance_to(c);
                    m.claim = Some((c, now + leg));
                    m.departed = now;
                }
                None => m.idle = Some(now),
            }
        }
        let Some(r) = (0..n)
            .filter(|&r| members[r].claim.is_some())
            .min_by(|&a, &b| {
                let at = |r: usize| members[r].claim.map_or(f64::INFINITY, |x| x.1);
                at(a).total_cmp(&at(b)).then(a.cmp(&b))
            })
        else {
            break;
        };
        let Some((c, arrival)) = members[r].claim.take() else {
            break;
        };
        now = arrival;
        arrive(&mut members, r, c, truth, &mut order, &mut finder)?;
        if members[r].search.goal_holds() {
            break;
        }
    }
    let goal_at = now;
    let holds = members[0].search.goal_holds();
    // Who brings what was found: every robot carrying a target; none carrying anything, the
    // one that gets there first goes empty-handed (so that one robot does what it always did).
    let mut ends = vec![goal_at; n];
    let mut legs = vec![0.0; n];
    let mut delivered = vec![false; n];
    let has_destination = members[0].search.destination().is_some();
    if has_destination {
        let carriers: Vec<usize> = (0..n).filter(|r| finder.contains(&Some(*r))).collect();
        let bring: Vec<usize> = if carriers.is_empty() {
            let reach = |r: usize| {
                let m = &members[r];
                let free = m.claim.map_or(m.idle.unwrap_or(goal_at), |x| x.1);
                let from = m
                    .claim
                    .map_or(m.search.belief().position(), |x| Place::Container(x.0));
                free + m
                    .search
                    .destination()
                    .map_or(f64::INFINITY, |d| d.from(from))
            };
            (0..n)
                .min_by(|&a, &b| reach(a).total_cmp(&reach(b)).then(a.cmp(&b)))
                .into_iter()
                .collect()
        } else {
            carriers
        };
        for r in bring {
            // A carrier under way finishes its leg (and searches there), then goes; one with
            // nothing left to search went as soon as it had nothing left.
            if let Some((c, arrival)) = members[r].claim.take() {
                ends[r] = arrival;
                arrive(&mut members, r, c, truth, &mut order, &mut finder)?;
            } else if let Some(since) = members[r].idle {
                ends[r] = since;
            }
            legs[r] = members[r].search.finish();
            ends[r] += legs[r];
            delivered[r] = true;
        }
    }
    // The last robot to get there ends the trial; its last leg is the trial's delivery.
    let last = (0..n)
        .filter(|&r| delivered[r])
        .max_by(|&a, &b| ends[a].total_cmp(&ends[b]).then(b.cmp(&a)));
    let makespan = last.map_or(goal_at, |r| ends[r].max(goal_at));
    let robots: Vec<RobotRun> = members
        .iter()
        .zip(&delivered)
        .map(|(m, &delivered)| {
            let under_way = m.claim.map_or(0.0, |_| goal_at - m.departed);
            RobotRun {
                searched: m.searched.clone(),
                travelled: m.search.belief().travelled() + under_way,
                heading: m.claim,
                delivered,
            }
        })
        .collect();
    let belief = members[0].search.belief();
    let found = goal_container(belief, &order, holds);
    // The destination as a place of the house's map (the first robot's, from its start).
    let delivered_to = members[0]
        .search
        .destination()
        .and_then(DestinationLegs::place)
        .filter(|_| delivered.contains(&true));
    let total_travel = robots.iter().map(|r| r.travelled).sum();
    Ok(TeamOutcome {
        trial: TrialOutcome {
            strategy: strategy.name().to_string(),
            task: first.trial.task.clone(),
            cost: makespan,
            searched: order.iter().map(|&(c, _)| c).collect(),
            found,
            found_each: belief.found_each().to_vec(),
            delivery: last.map_or(0.0, |r| legs[r]),
            delivered_to,
        },
        robots,
        searched_by: order.iter().map(|&(_, r)| r).collect(),
        total_travel,
    })
}

/// Robot `r` arrives at `c`: searches it and tells the others, or, when a teammate searched it
/// meanwhile, only gets there.
fn arrive(
    members: &mut [Member<'_>],
    r: usize,
    c: usize,
    truth: &GroundTruth,
    order: &mut Vec<(usize, usize)>,
    finder: &mut [Option<usize>],
) -> Result<(), PlanError> {
    if members[r].search.belief().is_searched(c) {
        members[r].search.visit(c);
        return Ok(());
    }
    let seen = contents_of(truth, c);
    let before: Vec<bool> = members[r]
        .search
        .belief()
        .found_each()
        .iter()
        .map(Option::is_some)
        .collect();
    members[r].search.record(c, seen.clone())?;
    for (t, was) in before.iter().enumerate() {
        if !was && members[r].search.belief().found(t).is_some() {
            finder[t] = Some(r);
        }
    }
    for (o, m) in members.iter_mut().enumerate() {
        if o != r {
            m.search.observe(c, seen.clone())?;
        }
    }
    members[r].searched.push(c);
    order.push((c, r));
    Ok(())
}

/// The containers robot `r` must leave to the others: their claims (coordinated, split) and,
/// split while its own share has containers left, every other share.
fn leaving(
    members: &[Member<'_>],
    r: usize,
    now: f64,
    teamwork: Teamwork,
    regions: Option<&[usize]>,
) -> Vec<usize> {
    if teamwork == Teamwork::Independent {
        return Vec::new();
    }
    // A claim is left to its robot when it gets there no later than this one would; one that
    // this robot would reach first stays open to it (the other's trip is then wasted, but the
    // container is searched sooner: what makes the goal hold early).
    let b = members[r].search.belief();
    let mut out: Vec<usize> = members
        .iter()
        .enumerate()
        .filter(|&(o, _)| o != r)
        .filter_map(|(_, m)| m.claim)
        .filter(|&(c, arrival)| arrival <= now + b.distance_to(c))
        .map(|(c, _)| c)
        .collect();
    if let Some(owner) = regions {
        let open = |c: usize| !b.is_searched(c) && !out.contains(&c);
        let mine_left = (0..owner.len()).any(|c| owner[c] == r && open(c));
        if mine_left {
            let others: Vec<usize> = (0..owner.len())
                .filter(|&c| owner[c] != r && open(c))
                .collect();
            out.extend(others);
        }
    }
    out
}

/// The container where the goal came to hold, as [`Search::goal_container`] says for one robot.
fn goal_container(belief: &Belief<'_>, order: &[(usize, usize)], holds: bool) -> Option<usize> {
    if !holds {
        return None;
    }
    let found: Vec<usize> = belief.found_each().iter().flatten().copied().collect();
    let rank = |c: &usize| order.iter().position(|x| x.0 == *c);
    match belief.task.goal() {
        Goal::All => found.iter().copied().max_by_key(rank),
        Goal::Any => found.iter().copied().min_by_key(rank),
    }
}

/// The rooms divided among robots starting at `starts`: the owner of each container. Rooms are
/// taken in the order of the angle of their containers' centre around the house's, from the
/// widest gap between neighbours, and cut into one run of neighbouring rooms per robot with
/// about as many containers each; the runs go to the robots so that the sum of the distances
/// from each robot's start to its run's centre is least (ties to the earlier assignment).
/// Containers of no room count as rooms of their own.
pub fn split_rooms(house: &House, starts: &[Point]) -> Vec<usize> {
    let n = starts.len().max(1);
    let count = house.containers.len();
    if n == 1 || count == 0 {
        return vec![0; count];
    }
    // Rooms by the containers they hold: (key, containers).
    let mut groups: Vec<(usize, Vec<usize>)> = Vec::new();
    for (c, container) in house.containers.iter().enumerate() {
        let key = container.room.map_or(house.rooms.len() + c, |r| r);
        match groups.iter_mut().find(|g| g.0 == key) {
            Some(g) => g.1.push(c),
            None => groups.push((key, vec![c])),
        }
    }
    let centre = |cs: &[usize]| {
        let (x, z) = cs.iter().fold((0.0, 0.0), |(x, z), &c| {
            let p = house.containers[c].position;
            (x + p.x, z + p.z)
        });
        Point::new(x / cs.len() as f64, z / cs.len() as f64)
    };
    let all: Vec<usize> = (0..count).collect();
    let middle = centre(&all);
    let angle = |p: Point| (p.z - middle.z).atan2(p.x - middle.x);
    let mut rooms: Vec<(f64, Vec<usize>)> = groups
        .into_iter()
        .map(|(_, cs)| (angle(centre(&cs)), cs))
        .collect();
    rooms.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Start the sweep after the widest angular gap, so that no run wraps across it.
    let gap_after = (0..rooms.len())
        .max_by(|&a, &b| {
            let gap = |i: usize| {
                let next = rooms[(i + 1) % rooms.len()].0;
                (next - rooms[i].0).rem_euclid(std::f64::consts::TAU)
            };
            gap(a).total_cmp(&gap(b)).then(b.cmp(&a))
        })
        .unwrap_or(0);
    let shift = (gap_after + 1) % rooms.len();
    rooms.rotate_left(shift);
    let mut runs: Vec<Vec<usize>> = vec![Vec::new(); n];
    let mut taken = 0usize;
    let mut run = 0usize;
    for (i, (_, cs)) in rooms.iter().enumerate() {
        // Each run closes once it reaches its share, leaving a room for every later run.
        let rooms_left = rooms.len() - i;
        let runs_left = n - run;
        if run + 1 < n
            && !runs[run].is_empty()
            && (taken * n >= count * (run + 1) || rooms_left < runs_left)
        {
            run += 1;
        }
        runs[run].extend(cs.iter().copied());
        taken += cs.len();
    }
    let centres: Vec<Option<Point>> = runs
        .iter()
        .map(|cs| (!cs.is_empty()).then(|| centre(cs)))
        .collect();
    let mut best: Option<(f64, Vec<usize>)> = None;
    for perm in permutations(n) {
        let cost: f64 = perm
            .iter()
            .enumerate()
            .filter_map(|(robot, &run)| centres[run].map(|c| starts[robot].distance(c)))
            .sum();
        if best.as_ref().is_none_or(|b| cost < b.0) {
            best = Some((cost, perm));
        }
    }
    let perm = best.map_or_else(|| (0..n).collect(), |b| b.1);
    let mut owner = vec![0; count];
    for (robot, &run) in perm.iter().enumerate() {
        for &c in &runs[run] {
            owner[c] = robot;
        }
    }
    owner
}

/// Every ordering of `0..n`, in lexicographic order (n ≤ [`MAX_ROBOTS`]: at most 24).
fn permutations(n: usize) -> Vec<Vec<usize>> {
    if n == 0 {
        return vec![Vec::new()];
    }
    let mut out = Vec::new();
    for rest in permutations(n - 1) {
        for i in 0..=rest.len() {
            let mut p = rest.clone();
            p.insert(i, n - 1);
            out.push(p);
        }
    }
    out.sort();
    out
}

/// A route and how long it takes, metres.
type Timed = (f64, Vec<usize>);

/// The team oracle: a route per robot through containers that hold the targets, so that the
/// goal holds (and, with a destination, every robot carrying a target stands there) as early
/// as possible. Exact: each robot's cheapest routes to every set of targets
/// ([`OracleTable`]), then the best division of the targets among the robots (`all`) or the
/// robot that reaches one first (`any`).
fn team_oracle_routes(
    problems: &[SearchProblem<'_>],
    truth: &GroundTruth,
) -> Result<Vec<Vec<usize>>, PlanError> {
    let Some(first) = problems.first() else {
        return Ok(Vec::new());
    };
    let task = first.task();
    let m = task.targets().len();
    let holds: Vec<u8> = (0..first.house.containers.len())
        .map(|c| {
            task.targets()
                .iter()
                .enumerate()
                .filter(|(_, t)| truth.holds(c, t))
                .fold(0u8, |mask, (i, _)| mask | (1 << i))
        })
        .collect();
    let full = ((1u16 << m) - 1) as u8;
    // best[r][mask]: robot r's least time to have found at least `mask` (and be at the
    // destination, with one), and the route.
    let mut best: Vec<Vec<Option<Timed>>> = Vec::with_capacity(problems.len());
    for p in problems {
        let mut belief = Belief::new(p.house, p.distances, task);
        for &c in &p.trial.revealed {
            belief.reveal(c, contents_of(truth, c));
        }
        let legs = p.destination_legs()?;
        let stop = |mask: u8| mask == full;
        let table = OracleTable::build(&belief, &holds, m, &stop);
        let end = |s: usize| {
            table.cost[s]
                + legs
                    .as_deref()
                    .map_or(0.0, |d| d.from(Place::Container(table.container(s))))
        };
        let mut row: Vec<Option<Timed>> = vec![None; usize::from(full) + 1];
        for (want, slot) in row.iter_mut().enumerate().skip(1) {
            let want = want as u8;
            let s = (0..table.cost.len())
                .filter(|&s| table.cost[s].is_finite() && table.mask(s) & want == want)
                .min_by(|&a, &b| end(a).total_cmp(&end(b)).then(a.cmp(&b)));
            *slot = s.map(|s| (end(s), table.route(s)));
        }
        best.push(row);
    }
    let n = problems.len();
    let mut routes = vec![Vec::new(); n];
    match task.goal() {
        Goal::Any => {
            let pick = (0..n)
                .flat_map(|r| (0..m).map(move |t| (r, 1u8 << t)))
                .filter_map(|(r, mask)| best[r][usize::from(mask)].as_ref().map(|b| (b.0, r, mask)))
                .min_by(|a, b| a.0.total_cmp(&b.0).then((a.1, a.2).cmp(&(b.1, b.2))));
            if let Some((_, r, mask)) = pick
                && let Some((_, route)) = &best[r][usize::from(mask)]
            {
                routes[r] = route.clone();
            }
        }
        Goal::All => {
            // Each target to a robot: n^m ≤ 256 divisions.
            let mut pick: Option<(f64, Vec<u8>)> = None;
            let divisions = n.pow(m as u32);
            for d in 0..divisions {
                let mut masks = vec![0u8; n];
                let mut k = d;
                for t in 0..m {
                    masks[k % n] |= 1 << t;
                    k /= n;
                }
                let span = masks
                    .iter()
                    .enumerate()
                    .map(|(r, &mask)| {
                        if mask == 0 {
                            Some(0.0)
                        } else {
                            best[r][usize::from(mask)].as_ref().map(|b| b.0)
                        }
                    })
                    .try_fold(0.0_f64, |a, b| b.map(|b| a.max(b)));
                if let Some(span) = span
                    && pick.as_ref().is_none_or(|p| span < p.0)
                {
                    pick = Some((span, masks));
                }
            }
            if let Some((_, masks)) = pick {
                for (r, mask) in masks.into_iter().enumerate() {
                    if mask != 0
                        && let Some((_, route)) = &best[r][usize::from(mask)]
                    {
                        routes[r] = route.clone();
                    }
                }
            }
        }
    }
    Ok(routes)
}
