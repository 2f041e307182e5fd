//! XYZ and CSV text: separators, comments, extra columns, a header line
//! of column names, and the errors.

mod common;

use std::path::Path;

use common::{PTS, assert_err_mentions};
use pcrnet_io::{Format, xyz};

/// `.csv` files read as XYZ text: a first line of column names is skipped,
/// a line that mixes names and numbers is still an error, and so are names
/// after the first point.
#[test]
fn csv_with_a_header() {
    assert_eq!(Format::from_path(Path::new("scan.CSV")), Some(Format::Csv));
    let csv = "x,y,z,intensity\n1,2,3,7\n-0.5,0.25,8,7\n";
    assert_eq!(Format::Csv.parse(csv.as_bytes()).unwrap(), &PTS[..2]);
    assert_eq!(
        Format::Xyz.parse(b"# scan\nX Y Z\n1 2 3\n").unwrap(),
        &PTS[..1]
    );
    for bad in ["1.0,abc,3\n1,2,3\n", "1,2,3\nx,y,z\n"] {
        let e = Format::Csv.parse(bad.as_bytes()).unwrap_err();
        assert!(e.to_string().contains("is not a number"), "{bad:?}: {e}");
    }
}

#[test]
fn xyz_separators_comments_and_extra_columns() {
    let f = "# x y z nx ny nz\n1 2 3\n\n  -0.5,0.25,8,0,0,1\n0.001\t-7.75 ,0 label # trailing\n\
             nan 1 1\n";
    assert_eq!(xyz::parse(f.as_bytes()).unwrap(), PTS);
    assert!(xyz::parse(b"").unwrap().is_empty());
}

#[test]
fn xyz_errors() {
    assert_err_mentions(
        xyz::parse(b"1 2 3\n4 5\n"),
        &["XYZ line 2", "expected 3 numbers, found 2"],
    );
    assert_err_mentions(
        xyz::parse(b"1 2 3\n\n4 5 six\n"),
        &["XYZ line 3", "z value", "six"],
    );
    // A first line of names alone is a header (`csv_with_a_header`); one
    // that mixes names and numbers is not.
    assert_err_mentions(xyz::parse(b"x,2,z\n1,2,3\n"), &["XYZ line 1", "x value"]);
    assert_err_mentions(xyz::parse(b"1 2 3\n\xff\xfe\n"), &["not text"]);
}
