//! Where a run starts: `eyebot-hil run --start NAME` (a course start named in the world file)
//! or `--start NORTH,EAST,HEADING` (a pose), in place of the configuration's `[start]`.

use std::str::FromStr;

use crate::daemon::config::Start;
use crate::physics::config::WorldConfig;

/// A `--start` value.
#[derive(Debug, Clone, PartialEq)]
pub enum StartChoice {
    /// A course start of the world file (`[starts.NAME]`, or `wall_following`).
    Named(String),
    /// North and east of the centre of mass (m) and compass heading (deg); the depth is the
    /// configuration's `[start]` depth.
    Pose {
        north_m: f64,
        east_m: f64,
        heading_deg: f64,
    },
}

impl FromStr for StartChoice {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let s = s.trim();
        if !s.contains(',') {
            let ok = !s.is_empty()
                && s.chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
            return if ok {
                Ok(StartChoice::Named(s.to_string()))
            } else {
                Err(format!(
                    "`{s}`: expected a course start name or NORTH,EAST,HEADING (m, m, deg)"
                ))
            };
        }
        let parts: Vec<&str> = s.split(',').map(str::trim).collect();
        let numbers: Option<Vec<f64>> = parts.iter().map(|p| p.parse::<f64>().ok()).collect();
        match numbers.as_deref() {
            Some(&[north_m, east_m, heading_deg])
                if [north_m, east_m, heading_deg].iter().all(|v| v.is_finite()) =>
            {
                Ok(StartChoice::Pose {
                    north_m,
                    east_m,
                    heading_deg,
                })
            }
            _ => Err(format!(
                "`{s}`: expected NORTH,EAST,HEADING: three numbers (m, m, deg), e.g. 2,1.5,0"
            )),
        }
    }
}

impl StartChoice {
    /// The start this choice names, given the configuration's `[start]` (for the depth of a
    /// pose) and the world (for the names); checked to lie inside the pool.
    pub fn resolve(&self, configured: &Start, world: &WorldConfig) -> Result<Start, String> {
        let start = match self {
            StartChoice::Named(name) => {
                let Some(s) = world.start_named(name) else {
                    let names: Vec<&str> = world.starts.iter().map(|s| s.name.as_str()).collect();
                    return Err(format!(
                        "--start {name}: no such course start in the world file; it names {}",
                        if names.is_empty() {
                            "none".to_string()
                        } else {
                            names.join(", ")
                        }
                    ));
                };
                Start {
                    position_m: s.position_m,
                    heading_deg: s.heading_deg,
                }
            }
            StartChoice::Pose {
                north_m,
                east_m,
                heading_deg,
            } => {
                if !(-360.0..=360.0).contains(heading_deg) {
                    return Err(format!(
                        "--start: heading {heading_deg} deg is not within -360..360"
                    ));
                }
                Start {
                    position_m: nalgebra::Vector3::new(*north_m, *east_m, configured.position_m.z),
                    heading_deg: *heading_deg,
                }
            }
        };
        match world.outside_pool(&start.position_m) {
            Some(why) => Err(format!("--start: {why}")),
            None => Ok(start),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_poses_parse() {
        assert_eq!(
            "wall_following".parse::<StartChoice>(),
            Ok(StartChoice::Named("wall_following".into()))
        );
        assert_eq!(
            " 2, 1.5 ,90".parse::<StartChoice>(),
            Ok(StartChoice::Pose {
                north_m: 2.0,
                east_m: 1.5,
                heading_deg: 90.0
            })
        );
        for bad in ["", "2,1.5", "2,x,0", "a b", "1,2,3,4", "1,inf,0"] {
            let err = bad.parse::<StartChoice>().expect_err(bad);
            assert!(err.contains("expected"), "{bad}: {err}");
        }
    }
}
