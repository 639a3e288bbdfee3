//! A tidy rule: terrain-demo's modules import no cycle (issue 33: the demo is glue whose parts
//! can be read, and moved into a library, one at a time). A module is a top-level file or
//! folder of `terrain-demo/src` (the viewer's `src/bin` apart); it imports another where its
//! code (comments and its `#[cfg(test)] mod tests` left out) names `crate::other`.

use crate::tidy::{Problem, TrackedFile};
use std::collections::{BTreeMap, BTreeSet};

/// The demo's sources, below which modules are read.
const DEMO_SRC: &str = "terrain-demo/src/";

/// One problem per cycle of imports between the demo's modules, at the first import of it.
pub fn import_cycles(files: &[&TrackedFile]) -> Vec<Problem> {
    // Module -> (imported module -> first file and line naming it).
    let mut graph: BTreeMap<String, BTreeMap<String, (String, usize)>> = BTreeMap::new();
    for f in files {
        let Some(rest) = f.path.strip_prefix(DEMO_SRC) else {
            continue;
        };
        if rest.starts_with("bin/") || !rest.ends_with(".rs") {
            continue;
        }
        let module = rest
            .split('/')
            .next()
            .unwrap_or(rest)
            .trim_end_matches(".rs");
        let edges = graph.entry(module.to_owned()).or_default();
        let code = f.text.split("#[cfg(test)]\nmod tests").next().unwrap_or("");
        // Comments out, lines kept (so offsets still give line numbers).
        let code: String = code
            .lines()
            .map(|l| l.split("//").next().unwrap_or(""))
            .collect::<Vec<_>>()
            .join("\n");
        for (at, _) in code.match_indices("crate::") {
            let named = &code[at + "crate::".len()..];
            // `crate::{a::X, b}` names each of the group's first segments.
            let names: Vec<&str> = match named.strip_prefix('{') {
                Some(group) => group
                    .split('}')
                    .next()
                    .unwrap_or("")
                    .split(',')
                    .map(str::trim)
                    .collect(),
                None => vec![named],
            };
            for name in names {
                let other: String = name
                    .chars()
                    .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
                    .collect();
                if !other.is_empty() && other != module {
                    let line = code[..at].matches('\n').count() + 1;
                    edges.entry(other).or_insert((f.path.clone(), line));
                }
            }
        }
    }
    let mut problems = Vec::new();
    let mut reported = BTreeSet::new();
    for start in graph.keys() {
        if let Some(cycle) = cycle_through(&graph, start)
            && reported.insert(canonical(&cycle))
        {
            let (path, line) = graph[&cycle[0]][&cycle[1]].clone();
            problems.push(Problem {
                path,
                line,
                message: format!(
                    "terrain-demo's modules import in a cycle: {} (move what they share into \
                     one of them, or into a library)",
                    cycle.join(" -> ")
                ),
            });
        }
    }
    problems
}

/// A path of imports from `start` back to it (`start` first and last), if any: a breadth-first
/// search, so the shortest.
fn cycle_through(
    graph: &BTreeMap<String, BTreeMap<String, (String, usize)>>,
    start: &str,
) -> Option<Vec<String>> {
    let mut came_from: BTreeMap<&str, &str> = BTreeMap::new();
    let mut queue = std::collections::VecDeque::from([start]);
    while let Some(m) = queue.pop_front() {
        for next in graph.get(m).into_iter().flat_map(|e| e.keys()) {
            if next == start {
                let mut path = vec![start.to_owned()];
                let mut at = m;
                while at != start {
                    path.insert(1, at.to_owned());
                    at = came_from[at];
                }
                path.push(start.to_owned());
                return Some(path);
            }
            if !came_from.contains_key(next.as_str()) && graph.contains_key(next) {
                came_from.insert(next, m);
                queue.push_back(next);
            }
        }
    }
    None
}

/// The cycle's modules, sorted: one report per cycle whichever module it was found from.
fn canonical(cycle: &[String]) -> Vec<String> {
    let mut set: Vec<String> = cycle[1..].to_vec();
    set.sort();
    set
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tidy::tests::file;

    #[test]
    fn a_cycle_between_demo_modules_is_reported_once() {
        let files = [
            file(
                "terrain-demo/src/driver.rs",
                "use crate::scenarios::Scenario;\n",
            ),
            file(
                "terrain-demo/src/scenarios/world.rs",
                "fn f() {}\nlet c = crate::driver::color();\n",
            ),
            file("terrain-demo/src/report.rs", "use crate::timings::Step;\n"),
            file("terrain-demo/src/timings.rs", "// see crate::report\n"),
            file(
                "terrain-demo/src/cli.rs",
                "fn a() {}\n#[cfg(test)]\nmod tests {\n    use crate::report;\n}\n",
            ),
            file(
                "terrain-demo/src/bin/viewer/main.rs",
                "use crate::driver;\n",
            ),
            file("terrain-gpu/src/lib.rs", "use crate::driver;\n"),
        ];
        let refs: Vec<&TrackedFile> = files.iter().collect();
        let problems = import_cycles(&refs);
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert_eq!(problems[0].path, "terrain-demo/src/driver.rs");
        assert_eq!(problems[0].line, 1);
        assert!(
            problems[0]
                .message
                .contains("driver -> scenarios -> driver")
        );
    }

    #[test]
    fn longer_cycles_are_found_and_a_tree_is_not_one() {
        let chain = [
            file("terrain-demo/src/a.rs", "use crate::b::X;\n"),
            file("terrain-demo/src/b.rs", "use crate::c::X;\n"),
            file(
                "terrain-demo/src/c.rs",
                "use crate::{\n    a::X,\n    d,\n};\n",
            ),
        ];
        let refs: Vec<&TrackedFile> = chain.iter().collect();
        let problems = import_cycles(&refs);
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert!(
            problems[0].message.contains("a -> b -> c -> a"),
            "{problems:?}"
        );
        let tree = [
            file(
                "terrain-demo/src/a.rs",
                "use crate::b::X;\nuse crate::c::Y;\n",
            ),
            file("terrain-demo/src/b.rs", "use crate::c::X;\n"),
            file("terrain-demo/src/c.rs", "\n"),
        ];
        let refs: Vec<&TrackedFile> = tree.iter().collect();
        assert!(import_cycles(&refs).is_empty());
    }
}
