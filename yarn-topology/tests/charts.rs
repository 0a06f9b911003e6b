//! Stitch kinds, named patterns and the plain-text chart format, through the
//! public API only.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use yarn_topology::{Chart, Pattern, StitchKind, TopologyError};

use StitchKind::{Knit as K, Purl as P};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

fn count(chart: &Chart, kind: StitchKind) -> usize {
    (0..chart.height())
        .flat_map(|row| (0..chart.width()).map(move |column| (column, row)))
        .filter(|&(c, r)| chart.get(c, r) == Some(kind))
        .count()
}

#[test]
fn knit_is_the_default_and_its_legs_lie_toward_the_face() {
    assert_eq!(StitchKind::default(), K);
    assert_eq!((K.sign(), P.sign()), (1.0, -1.0));
    assert_eq!((K.letter(), P.letter()), ('k', 'p'));
    for letter in ['k', 'K'] {
        assert_eq!(StitchKind::from_letter(letter), Some(K));
    }
    for letter in ['p', 'P'] {
        assert_eq!(StitchKind::from_letter(letter), Some(P));
    }
    for letter in ['x', ' ', '#', '.', 'é'] {
        assert_eq!(StitchKind::from_letter(letter), None, "{letter:?}");
    }
}

#[test]
fn each_pattern_has_its_knit_and_purl_counts() {
    // (pattern, width, height, knit stitches); the rest are purl.
    let cases = [
        (Pattern::Stockinette, 4, 3, 12),
        (Pattern::ReverseStockinette, 4, 3, 0),
        (Pattern::Garter, 4, 3, 8), // rows 0 and 2 knit
        (Pattern::Garter, 4, 4, 8),
        (Pattern::Rib1x1, 5, 3, 9), // knit columns 0, 2, 4
        (Pattern::Rib1x1, 4, 2, 4),
        (Pattern::Rib2x2, 5, 3, 9), // k k p p k: knit columns 0, 1, 4
        (Pattern::Rib2x2, 6, 1, 4), // k k p p k k
        (Pattern::Rib2x2, 8, 2, 8),
        (Pattern::Seed, 3, 3, 5),
        (Pattern::Seed, 4, 2, 4),
        (Pattern::Seed, 1, 1, 1),
    ];
    for (pattern, width, height, knit) in cases {
        let chart = pattern.chart(width, height).unwrap();
        assert_eq!((chart.width(), chart.height()), (width, height), "{pattern} {width}x{height}");
        assert_eq!(count(&chart, K), knit, "{pattern} {width}x{height}: knit");
        assert_eq!(count(&chart, P), width * height - knit, "{pattern} {width}x{height}: purl");
    }
}

#[test]
fn each_pattern_has_its_stitch_in_chosen_cells() {
    // (pattern, column, row, stitch), row 0 at the bottom, column 0 at the left.
    let cases = [
        (Pattern::Stockinette, 3, 5, K),
        (Pattern::ReverseStockinette, 0, 0, P),
        (Pattern::ReverseStockinette, 6, 3, P),
        (Pattern::Garter, 0, 0, K),
        (Pattern::Garter, 6, 0, K),
        (Pattern::Garter, 3, 1, P),
        (Pattern::Garter, 3, 2, K),
        (Pattern::Garter, 0, 7, P),
        (Pattern::Rib1x1, 0, 0, K),
        (Pattern::Rib1x1, 1, 0, P),
        (Pattern::Rib1x1, 3, 6, P),
        (Pattern::Rib1x1, 4, 7, K),
        (Pattern::Rib2x2, 1, 0, K),
        (Pattern::Rib2x2, 2, 0, P),
        (Pattern::Rib2x2, 3, 5, P),
        (Pattern::Rib2x2, 4, 5, K),
        (Pattern::Rib2x2, 7, 1, P),
        (Pattern::Seed, 0, 0, K),
        (Pattern::Seed, 1, 0, P),
        (Pattern::Seed, 0, 1, P),
        (Pattern::Seed, 1, 1, K),
        (Pattern::Seed, 4, 7, P),
    ];
    for (pattern, column, row, stitch) in cases {
        assert_eq!(pattern.stitch(column, row), stitch, "{pattern} ({column}, {row})");
        let chart = pattern.chart(8, 8).unwrap();
        assert_eq!(chart.get(column, row), Some(stitch), "{pattern} chart ({column}, {row})");
    }
    // The rule holds at any cell, even where row + column would overflow.
    assert_eq!(Pattern::Seed.stitch(usize::MAX, usize::MAX), K);
    assert_eq!(Pattern::Seed.stitch(usize::MAX, 0), P);
    assert_eq!(Pattern::Rib2x2.stitch(usize::MAX, 0), P);
}

#[test]
fn pattern_charts_read_as_printed_charts_top_row_first() {
    // Sizes whose rows differ from bottom to top, so the row order shows.
    let cases = [
        (Pattern::Garter, 3, 4, "ppp\nkkk\nppp\nkkk\n"),
        (Pattern::Seed, 4, 2, "pkpk\nkpkp\n"),
        (Pattern::Rib1x1, 5, 2, "kpkpk\nkpkpk\n"),
        (Pattern::Rib2x2, 6, 2, "kkppkk\nkkppkk\n"),
        (Pattern::Stockinette, 2, 1, "kk\n"),
        (Pattern::ReverseStockinette, 1, 2, "p\np\n"),
    ];
    for (pattern, width, height, text) in cases {
        assert_eq!(pattern.chart(width, height).unwrap().to_text(), text, "{pattern}");
    }
}

#[test]
fn chart_stockinette_is_the_stockinette_pattern() {
    for (width, height) in [(1, 1), (3, 2), (16, 16)] {
        assert_eq!(Chart::stockinette(width, height), Pattern::Stockinette.chart(width, height));
    }
    assert_eq!(Chart::stockinette(0, 2), Pattern::Stockinette.chart(0, 2));
}

#[test]
fn pattern_charts_check_their_size() {
    for pattern in Pattern::ALL {
        assert_eq!(pattern.chart(0, 3), Err(TopologyError::EmptyChart { width: 0, height: 3 }), "{pattern}");
        assert_eq!(pattern.chart(3, 0), Err(TopologyError::EmptyChart { width: 3, height: 0 }), "{pattern}");
        assert!(matches!(pattern.chart(usize::MAX, 2), Err(TopologyError::TooLarge { .. })), "{pattern}");
    }
}

#[test]
fn every_pattern_name_parses_back_to_its_pattern() {
    let names = ["stockinette", "reverse-stockinette", "garter", "rib-1x1", "rib-2x2", "seed"];
    assert_eq!(Pattern::ALL.map(Pattern::name), names);
    for pattern in Pattern::ALL {
        assert_eq!(pattern.name().parse::<Pattern>(), Ok(pattern));
        assert_eq!(pattern.to_string(), pattern.name());
    }
}

#[test]
fn an_unknown_pattern_name_lists_every_valid_name() {
    for name in ["rib", "Garter", " seed", "", "rib-3x3"] {
        let err = name.parse::<Pattern>().unwrap_err();
        assert_eq!(err, TopologyError::UnknownPattern { name: name.to_owned() });
        let message = err.to_string();
        assert!(message.contains(&format!("`{name}`")), "{message}");
        for pattern in Pattern::ALL {
            assert!(message.contains(pattern.name()), "{message} lacks {pattern}");
        }
    }
}

#[test]
fn a_garter_file_with_comments_and_mixed_case_is_garter() {
    let chart = Chart::from_file(&data("garter.txt")).unwrap();
    assert_eq!(chart, Pattern::Garter.chart(5, 4).unwrap());
}

#[test]
fn the_last_line_of_a_text_chart_is_row_0() {
    let chart = Chart::from_file(&data("asymmetric.txt")).unwrap();
    let rows_from_the_bottom = [[K, K, K, P], [K, P, P, P], [K, P, P, K]];
    assert_eq!(chart, Chart::new(4, 3, rows_from_the_bottom.concat()).unwrap());
    assert_eq!((chart.get(3, 0), chart.get(3, 2), chart.get(0, 2)), (Some(P), Some(K), Some(K)));
}

#[test]
fn whitespace_line_ends_and_comments_are_ignored() {
    let expected = Chart::new(3, 2, vec![K, P, K, P, P, K]).unwrap();
    for text in [
        "ppk\nkpk",
        "ppk\r\nkpk\r\n",
        "\u{feff}ppk\nkpk\n",
        "  p\tp k  \n\n k p k\n\n\n",
        "# top\nppk # row 2\n   # between\nkpk#row 1\n# end",
        "PPK\nKpK\n",
    ] {
        assert_eq!(Chart::parse(text), Ok(expected.clone()), "{text:?}");
    }
}

#[test]
fn a_bad_character_names_row_line_column_and_character() {
    let err = Chart::from_file(&data("bad-stitch.txt")).unwrap_err();
    assert_eq!(err, TopologyError::BadStitch { row: 2, line: 4, column: 3, found: 'x' });
    let message = err.to_string();
    for part in ["chart row 2", "line 4", "column 3", "'x'", "k for knit", "p for purl"] {
        assert!(message.contains(part), "{message} lacks {part}");
    }
}

#[test]
fn bad_characters_count_stitch_columns_not_bytes_or_spaces() {
    assert_eq!(Chart::parse("kék"), Err(TopologyError::BadStitch { row: 1, line: 1, column: 2, found: 'é' }));
    assert_eq!(Chart::parse("k  k\tk . k"), Err(TopologyError::BadStitch { row: 1, line: 1, column: 4, found: '.' }));
    // In one row a bad character is named before the row's width.
    assert_eq!(Chart::parse("kxkk\nkk"), Err(TopologyError::BadStitch { row: 2, line: 1, column: 2, found: 'x' }));
    // Rows are read from the bottom, so the lowest bad row is named.
    assert_eq!(Chart::parse("k0\nkk\nk\n"), Err(TopologyError::RaggedRow { row: 2, line: 2, width: 2, expected: 1 }));
    assert_eq!(Chart::parse("x\nkkk\nk?\n"), Err(TopologyError::BadStitch { row: 1, line: 3, column: 2, found: '?' }));
}

#[test]
fn a_ragged_row_names_row_line_and_both_widths() {
    let err = Chart::from_file(&data("ragged.txt")).unwrap_err();
    assert_eq!(err, TopologyError::RaggedRow { row: 2, line: 2, width: 3, expected: 4 });
    let message = err.to_string();
    for part in ["chart row 2", "line 2", "3 stitches", "row 1", "is 4", "same number"] {
        assert!(message.contains(part), "{message} lacks {part}");
    }
    assert_eq!(Chart::parse("kkkkk\nkkkk"), Err(TopologyError::RaggedRow { row: 2, line: 1, width: 5, expected: 4 }));
}

#[test]
fn a_text_without_rows_is_an_empty_chart() {
    assert_eq!(Chart::from_file(&data("empty.txt")), Err(TopologyError::EmptyChartText));
    for text in ["", "\n", "   \n\t\n", "# k p\n#kkk"] {
        assert_eq!(Chart::parse(text), Err(TopologyError::EmptyChartText), "{text:?}");
    }
}

#[test]
fn a_missing_file_names_its_path() {
    let path = data("no-such-chart.txt");
    let Err(TopologyError::ReadChart { path: reported, message }) = Chart::from_file(&path) else {
        panic!("a missing file must be a ReadChart error");
    };
    assert_eq!(reported, path);
    assert!(!message.is_empty());
    let shown = TopologyError::ReadChart { path: path.clone(), message }.to_string();
    assert!(shown.contains("no-such-chart.txt"), "{shown}");
}

proptest! {
    #[test]
    fn every_pattern_round_trips_through_text(index in 0..Pattern::ALL.len(), width in 1usize..14, height in 1usize..14) {
        let chart = Pattern::ALL[index].chart(width, height).unwrap();
        prop_assert_eq!(Chart::parse(&chart.to_text()), Ok(chart));
    }

    #[test]
    fn any_chart_round_trips_through_text(
        (width, height, knits) in (1usize..12, 1usize..12)
            .prop_flat_map(|(w, h)| (Just(w), Just(h), proptest::collection::vec(any::<bool>(), w * h)))
    ) {
        let stitches = knits.into_iter().map(|knit| if knit { K } else { P }).collect();
        let chart = Chart::new(width, height, stitches).unwrap();
        let text = chart.to_text();
        prop_assert_eq!(text.lines().count(), height);
        prop_assert_eq!(Chart::parse(&text), Ok(chart));
    }
}
