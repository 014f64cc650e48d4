//! Minimal file-name patterns for manifests: `*` (any run of characters but `/`), `?` (one
//! character) and `[…]` classes (`[1-7]`, `[FA]`, `[!L]`) in any path component. Matches are
//! returned in natural order (`ADL2` before `ADL10`).

use std::path::{Component, Path, PathBuf};

/// `true` when `s` contains a pattern character.
pub fn is_pattern(s: &str) -> bool {
    s.contains(['*', '?', '['])
}

/// Expands a pattern to the existing paths it matches (sorted naturally). A path without
/// pattern characters is returned as is (whether or not it exists).
pub fn expand(pattern: &Path) -> Vec<PathBuf> {
    let text = pattern.to_string_lossy();
    if !is_pattern(&text) {
        return vec![pattern.to_path_buf()];
    }
    let mut current: Vec<PathBuf> = vec![PathBuf::new()];
    for comp in pattern.components() {
        let mut next = Vec::new();
        match comp {
            Component::Normal(c) if is_pattern(&c.to_string_lossy()) => {
                let pat: Vec<char> = c.to_string_lossy().chars().collect();
                for base in &current {
                    let dir = if base.as_os_str().is_empty() {
                        Path::new(".")
                    } else {
                        base
                    };
                    let Ok(entries) = std::fs::read_dir(dir) else {
                        continue;
                    };
                    let mut names: Vec<String> = entries
                        .filter_map(Result::ok)
                        .map(|e| e.file_name().to_string_lossy().into_owned())
                        .filter(|n| {
                            !n.starts_with('.') && matches(&pat, &n.chars().collect::<Vec<_>>())
                        })
                        .collect();
                    names.sort_by(|a, b| natord::compare(a, b));
                    next.extend(names.into_iter().map(|n| base.join(n)));
                }
            }
            other => next.extend(current.iter().map(|b| b.join(other.as_os_str()))),
        }
        current = next;
    }
    current.retain(|p| p.exists());
    current
}

/// Whether `name` matches the pattern `pat` (one path component).
pub fn matches(pat: &[char], name: &[char]) -> bool {
    match pat.first() {
        None => name.is_empty(),
        Some('*') => (0..=name.len()).any(|k| matches(&pat[1..], &name[k..])),
        Some('?') => !name.is_empty() && matches(&pat[1..], &name[1..]),
        Some('[') => {
            let Some(close) = pat.iter().skip(2).position(|&c| c == ']').map(|k| k + 2) else {
                return name.first() == Some(&'[') && matches(&pat[1..], &name[1..]);
            };
            let Some(&c) = name.first() else { return false };
            let mut class = &pat[1..close];
            let negate = matches!(class.first(), Some('!' | '^'));
            if negate {
                class = &class[1..];
            }
            let mut hit = false;
            let mut k = 0;
            while k < class.len() {
                if k + 2 < class.len() && class[k + 1] == '-' {
                    hit |= class[k] <= c && c <= class[k + 2];
                    k += 3;
                } else {
                    hit |= class[k] == c;
                    k += 1;
                }
            }
            hit != negate && matches(&pat[close + 1..], &name[1..])
        }
        Some(&p) => name.first() == Some(&p) && matches(&pat[1..], &name[1..]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn m(p: &str, n: &str) -> bool {
        matches(
            &p.chars().collect::<Vec<_>>(),
            &n.chars().collect::<Vec<_>>(),
        )
    }

    #[test]
    fn patterns() {
        assert!(m("ADL00[1-7]", "ADL003"));
        assert!(!m("ADL00[1-7]", "ADL008"));
        assert!(m("*[FA]R?.csv.xz", "ADL001FR3.csv.xz"));
        assert!(!m("*[FA]R?.csv.xz", "ADL001DR3.csv.xz"));
        assert!(m("*[!D]R?.csv", "ADL001AR3.csv"));
        assert!(m("a*b*c", "aXXbYc"));
        assert!(!m("a?", "a"));
    }

    #[test]
    fn expands_in_a_directory() {
        let dir = tempfile::tempdir().unwrap();
        for n in ["s2", "s10", "s1"] {
            std::fs::create_dir(dir.path().join(n)).unwrap();
            std::fs::write(dir.path().join(n).join("t.csv"), "").unwrap();
        }
        let got = expand(&dir.path().join("s*/t.csv"));
        let names: Vec<_> = got
            .iter()
            .map(|p| p.parent().unwrap().file_name().unwrap().to_owned())
            .collect();
        assert_eq!(names, ["s1", "s2", "s10"]);
    }
}
