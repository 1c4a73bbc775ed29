//! "Did you mean …?" for column headers.
//!
//! Site loggers name columns like `PWD12_MOR (m)`; a hand-edited export easily
//! becomes `PWD12_MOR(m)` or `pwd12_mor (m)`. These helpers find the header a
//! user most likely meant so that errors can say so.

/// Edit distance between two strings, counted in characters.
///
/// Hand-written: a 15-line dynamic programme does not justify a dependency
/// (strsim) for the handful of header comparisons made per campaign.
pub(crate) fn levenshtein(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    let mut cur = vec![0; b.len() + 1];
    for (i, ca) in a.chars().enumerate() {
        cur[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let sub = prev[j] + usize::from(ca != *cb);
            cur[j + 1] = sub.min(prev[j + 1] + 1).min(cur[j] + 1);
        }
        std::mem::swap(&mut prev, &mut cur);
    }
    prev[b.len()]
}

/// A header with case, spaces and underscores removed, so that
/// `PWD12_MOR(m)`, `pwd12_mor (m)` and `PWD12 MOR (m)` compare equal.
pub(crate) fn normalize(header: &str) -> String {
    header
        .chars()
        .filter(|c| !c.is_whitespace() && *c != '_' && *c != '-')
        .flat_map(char::to_lowercase)
        .collect()
}

/// True when `found` is probably a misspelling of `known`: equal after
/// [`normalize`], or within a small edit distance (1 for names of 4 to 9
/// characters, 2 from 10 on; none below 4 so that short names do not all
/// match).
pub(crate) fn is_close(found: &str, known: &str) -> bool {
    if found == known {
        return false;
    }
    if normalize(found) == normalize(known) {
        return true;
    }
    let budget = match known.chars().count() {
        0..4 => 0,
        4..10 => 1,
        _ => 2,
    };
    budget > 0 && levenshtein(found, known) <= budget
}

/// The header of `headers` (with its index) that is closest to `wanted`,
/// when one is close enough to be a likely misspelling.
pub(crate) fn nearest<'a>(
    wanted: &str,
    headers: impl IntoIterator<Item = (usize, &'a str)>,
) -> Option<(usize, &'a str)> {
    headers
        .into_iter()
        .filter(|(_, h)| is_close(h, wanted))
        .min_by_key(|(i, h)| (levenshtein(&normalize(h), &normalize(wanted)), *i))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distance_known_answers() {
        assert_eq!(levenshtein("", "abc"), 3);
        assert_eq!(levenshtein("kitten", "sitting"), 3);
        assert_eq!(levenshtein("PWD12_MOR(m)", "PWD12_MOR (m)"), 1);
        assert_eq!(levenshtein("°C", "°C"), 0);
    }

    #[test]
    fn close_headers() {
        assert!(is_close("PWD12_MOR(m)", "PWD12_MOR (m)"));
        assert!(is_close("pwd12_mor (m)", "PWD12_MOR (m)"));
        assert!(is_close("VS2K_MOR (n)", "VS2K_MOR (m)"));
        assert!(!is_close("VS2K_MOR (m)", "VS2K_MOR (m)"));
        assert!(!is_close("wind speed (m/s)", "PWD12_MOR (m)"));
        // Two sensors of the same quantity are not misspellings of each other
        // once the name is short enough for a 1-edit budget to matter.
        assert!(!is_close("id", "ix"));
        assert!(is_close("kep", "keep"));
        assert!(!is_close("kept", "keep"), "two edits on a 4-letter name");
    }

    #[test]
    fn nearest_prefers_the_smallest_edit() {
        let headers = ["recording", "PWD12_MOR(m)", "PWD12_MOR (km)"];
        let got = nearest("PWD12_MOR (m)", headers.iter().copied().enumerate());
        assert_eq!(got, Some((1, "PWD12_MOR(m)")));
    }
}
