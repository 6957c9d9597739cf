//! The C library's HDT motor table (`firmware-protocol/c/eb_hdt.c`) equals the `hdt_duty`
//! tables of `configs/vehicles/mako.toml`. `EYEBOT_HDT_REGENERATE=1` rewrites the C table
//! from the TOML instead of failing.

use eyebot_test_support::eyebot_c::c_source_dir;
use eyebot_test_support::workspace_root;

const BEGIN: &str = "static const uint16_t hdt_duty_x10[4][11] = {\n";
const END: &str = "};\n";

fn expected_rows() -> String {
    let text = std::fs::read_to_string(workspace_root().join("configs/vehicles/mako.toml"))
        .expect("mako.toml");
    let doc: toml::Table = text.parse().expect("mako.toml parses");
    let thrusters = doc["thruster"].as_array().expect("[[thruster]]");
    assert_eq!(thrusters.len(), 4, "port, starboard, bow, stern");
    let mut rows = String::new();
    for t in thrusters {
        let name = t["name"].as_str().expect("name");
        let duty = t["hdt_duty"].as_array().expect("hdt_duty");
        assert_eq!(duty.len(), 11, "{name}: 0..100 % in 10 % steps");
        let cells: Vec<String> = duty
            .iter()
            .map(|v| {
                let d = v
                    .as_float()
                    .or(v.as_integer().map(|i| i as f64))
                    .expect("number");
                assert!((0.0..=255.0).contains(&d), "{name}: duty {d}");
                format!("{}", (d * 10.0).round() as i64)
            })
            .collect();
        rows.push_str(&format!("    {{{}}}, /* {name} */\n", cells.join(", ")));
    }
    rows
}

#[test]
fn c_hdt_table_matches_mako_toml() {
    let path = c_source_dir().join("eb_hdt.c");
    let c = std::fs::read_to_string(&path).expect("eb_hdt.c");
    let start = c.find(BEGIN).expect("table start") + BEGIN.len();
    let end = start + c[start..].find(END).expect("table end");
    let expected = expected_rows();
    if c[start..end] == expected {
        return;
    }
    if std::env::var_os("EYEBOT_HDT_REGENERATE").is_some() {
        let updated = format!("{}{}{}", &c[..start], expected, &c[end..]);
        std::fs::write(&path, updated).expect("write eb_hdt.c");
        eprintln!("regenerated {}", path.display());
        return;
    }
    panic!(
        "{} differs from configs/vehicles/mako.toml; expected rows:\n{expected}\n\
         run EYEBOT_HDT_REGENERATE=1 cargo test --test eyebot_c_hdt",
        path.display()
    );
}
