//! What the viewer shows, and the edits it makes to the scene file: the
//! camera, the sun, the medium's density, the shafts' planes, the lights'
//! positions, the passes turned off, the clock and the sample count. Pure
//! (no window): the key bindings and the camera's motion are unit-tested.

use crate::scene::SceneFile;
use glam::{Quat, Vec3};
use std::collections::BTreeSet;

/// The view: the scene file's settings as the user has changed them.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewState {
    pub position: Vec3,
    pub look_at: Vec3,
    pub up: Vec3,
    /// Window size in pixels: the render's resolution.
    pub size: [u32; 2],
    /// Sub-pixel samples accumulated while nothing changes (`--spp`).
    pub samples: u32,
    /// Degrees added to the sun's zenith and azimuth (`[sky]`, and the
    /// directional lights turned with it).
    pub sun_turn: [f32; 2],
    /// Factor on every scattering and extinction coefficient (the
    /// `[medium]` and each `[[volume]]`).
    pub density: f32,
    /// The shafts' sample planes and sub-planes, when changed here.
    pub planes: Option<u32>,
    pub subplanes: Option<u32>,
    /// Metres added to each movable light's position (spotlights, then
    /// point lights).
    pub light_moves: Vec<Vec3>,
    /// The light the movement keys move (`None`: they move the camera).
    pub selected_light: Option<usize>,
    /// Passes turned off, by name.
    pub disabled: BTreeSet<String>,
    /// Seconds after the scene's `[time] seconds` (the worker sets the
    /// instant: `SceneData::at_time`).
    pub time: f64,
}

/// The shafts' plane counts the keys step through stay inside what a scene
/// file may hold (`shafts::Settings::validate`'s limits are the real check).
const MIN_PLANES: u32 = 2;
const MAX_PLANES: u32 = 4096;
const MAX_SUBPLANES: u32 = 64;
/// The polar angle the orbit keeps from straight up or down (radians): at
/// the pole the camera's `up` and view direction would be parallel.
const POLE_MARGIN: f32 = 0.02;

impl ViewState {
    /// The view a scene file sets up, at `size` pixels.
    pub fn of(file: &SceneFile, size: [u32; 2], samples: u32) -> ViewState {
        let lights = file.spotlight.len() + file.point_light.len();
        ViewState {
            position: Vec3::from(file.camera.position),
            look_at: Vec3::from(file.camera.look_at),
            up: Vec3::from(file.camera.up),
            size,
            samples,
            sun_turn: [0.0; 2],
            density: 1.0,
            planes: None,
            subplanes: None,
            light_moves: vec![Vec3::ZERO; lights],
            selected_light: None,
            disabled: BTreeSet::new(),
            time: 0.0,
        }
    }

    /// Writes the view into a scene file (then built and validated as any
    /// file is: `SceneData::reconfigure`).
    pub fn apply(&self, file: &mut SceneFile) {
        file.camera.position = self.position.into();
        file.camera.look_at = self.look_at.into();
        file.camera.up = self.up.into();
        file.camera.resolution = self.size;
        file.camera.samples_per_pixel = self.samples;
        let [dz, da] = self.sun_turn;
        if let Some(sky) = &mut file.sky {
            sky.sun_zenith_deg = (sky.sun_zenith_deg + dz).clamp(0.0, 180.0);
            sky.sun_azimuth_deg = (sky.sun_azimuth_deg + da).rem_euclid(360.0);
        }
        if dz != 0.0 || da != 0.0 {
            for light in &mut file.directional_light {
                light.direction = turn_direction(Vec3::from(light.direction), dz, da).into();
            }
        }
        if self.density != 1.0 {
            let scale = |c: &mut [f32; 3]| c.iter_mut().for_each(|v| *v *= self.density);
            scale(&mut file.medium.sigma_s);
            scale(&mut file.medium.sigma_t);
            for v in &mut file.volume {
                scale(&mut v.sigma_s);
                scale(&mut v.sigma_t);
            }
        }
        if let Some(p) = self.planes {
            file.shafts.planes = p;
        }
        if let Some(s) = self.subplanes {
            file.shafts.subplanes = s;
        }
        let spots = file.spotlight.len();
        for (k, d) in self.light_moves.iter().enumerate() {
            let p = if k < spots {
                &mut file.spotlight[k].position
            } else if let Some(l) = file.point_light.get_mut(k - spots) {
                &mut l.position
            } else {
                continue;
            };
            *p = (Vec3::from(*p) + *d).into();
        }
    }

    /// The view direction (unit).
    pub fn forward(&self) -> Vec3 {
        (self.look_at - self.position).normalize_or(Vec3::NEG_Z)
    }

    /// A step of the movement keys: 4 % of the distance to the point looked
    /// at (so it suits a 1 m room and a 10 km sea alike), at least 1 cm.
    pub fn step(&self) -> f32 {
        (0.04 * (self.look_at - self.position).length()).max(0.01)
    }

    /// Orbits the camera around the point it looks at: `yaw` about the up
    /// axis, `pitch` toward it (radians), keeping the distance.
    pub fn orbit(&mut self, yaw: f32, pitch: f32) {
        let up = self.up.normalize_or(Vec3::Y);
        let offset = self.position - self.look_at;
        let r = offset.length();
        if r == 0.0 {
            return;
        }
        let polar = (offset.dot(up) / r).clamp(-1.0, 1.0).acos();
        // The change of the polar angle from `up` (negative: higher).
        let turn = (polar - pitch).clamp(POLE_MARGIN, std::f32::consts::PI - POLE_MARGIN) - polar;
        let right = up.cross(offset).normalize_or(Vec3::X);
        let turned = Quat::from_axis_angle(up, yaw) * (Quat::from_axis_angle(right, turn) * offset);
        self.position = self.look_at + turned;
    }

    /// Moves the camera toward the point it looks at by `factor` of the
    /// distance (negative: away), never onto it.
    pub fn dolly(&mut self, factor: f32) {
        let offset = self.position - self.look_at;
        let scaled = offset * (1.0 - factor).max(0.05);
        self.position = self.look_at + scaled;
    }

    /// Moves the camera, or the selected light, by `steps` along the view's
    /// right, up and forward axes.
    pub fn fly(&mut self, steps: Vec3) {
        let forward = self.forward();
        let right = forward.cross(self.up).normalize_or(Vec3::X);
        let up = right.cross(forward);
        let d = (right * steps.x + up * steps.y + forward * steps.z) * self.step();
        match self.selected_light {
            Some(k) if k < self.light_moves.len() => self.light_moves[k] += d,
            _ => {
                self.position += d;
                self.look_at += d;
            }
        }
    }

    /// Halves or doubles the shafts' planes (`current`: the scene's count).
    pub fn scale_planes(&mut self, current: u32, double: bool) {
        let p = self.planes.unwrap_or(current);
        self.planes = Some(if double { (p * 2).min(MAX_PLANES) } else { (p / 2).max(MIN_PLANES) });
    }

    /// One sub-plane more or fewer (`current`: the scene's count).
    pub fn step_subplanes(&mut self, current: u32, more: bool) {
        let s = self.subplanes.unwrap_or(current);
        self.subplanes = Some(if more { (s + 1).min(MAX_SUBPLANES) } else { s.saturating_sub(1) });
    }

    /// Selects the next movable light, and after the last none (the keys
    /// move the camera again).
    pub fn select_next_light(&mut self) {
        let n = self.light_moves.len();
        self.selected_light = match self.selected_light {
            _ if n == 0 => None,
            None => Some(0),
            Some(k) if k + 1 < n => Some(k + 1),
            Some(_) => None,
        };
    }

    /// Turns a pass off, or on again.
    pub fn toggle_pass(&mut self, name: &str) {
        if !self.disabled.remove(name) {
            self.disabled.insert(name.to_string());
        }
    }

    /// The camera as a `[camera]` table to paste into a scene file.
    pub fn camera_toml(&self, file: &SceneFile) -> String {
        let v = |v: Vec3| format!("[{}, {}, {}]", v.x, v.y, v.z);
        let mut out = String::from("[camera]\n");
        out += &format!("position = {}\nlook_at = {}\nup = {}\n", v(self.position), v(self.look_at), v(self.up));
        if let Some(f) = file.camera.vfov_deg {
            out += &format!("vfov_deg = {f}\n");
        }
        if file.camera.projection == crate::scene::Projection::Fisheye {
            out += "projection = \"fisheye\"\n";
        }
        out += &format!("resolution = [{}, {}]\n", self.size[0], self.size[1]);
        if file.camera.exposure != 1.0 {
            out += &format!("exposure = {}\n", file.camera.exposure);
        }
        out
    }
}

/// A light's direction (from the light into the scene) with the sun it
/// stands for moved by `dz` degrees of zenith angle and `da` of azimuth
/// (the sky's convention: y up, azimuth from +z toward +x).
fn turn_direction(direction: Vec3, dz: f32, da: f32) -> Vec3 {
    let to_sun = -direction.normalize_or(Vec3::NEG_Y);
    let zenith = (to_sun.y.clamp(-1.0, 1.0).acos() + dz.to_radians()).clamp(0.0, std::f32::consts::PI);
    let azimuth = to_sun.x.atan2(to_sun.z) + da.to_radians();
    -Vec3::new(zenith.sin() * azimuth.sin(), zenith.cos(), zenith.sin() * azimuth.cos()) * direction.length()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file() -> SceneFile {
        toml::from_str(
            r#"
            [camera]
            position = [0.0, 1.0, 5.0]
            look_at = [0.0, 1.0, 0.0]
            vfov_deg = 40.0
            resolution = [64, 48]
            [[spotlight]]
            position = [0.0, 3.0, 0.0]
            direction = [0.0, -1.0, 0.0]
            cutoff_deg = 20.0
            intensity = [1.0, 1.0, 1.0]
            [[directional_light]]
            direction = [0.0, -1.0, -1.0]
            irradiance = [1.0, 1.0, 1.0]
            "#,
        )
        .expect("a valid scene")
    }

    #[test]
    fn an_untouched_view_leaves_the_file_as_it_was_but_for_its_size() {
        let f = file();
        let mut g = f.clone();
        ViewState::of(&f, [64, 48], 1).apply(&mut g);
        assert_eq!(format!("{:?}", f), format!("{:?}", g));
    }

    #[test]
    fn orbit_keeps_the_distance_and_stops_short_of_the_pole() {
        let mut v = ViewState::of(&file(), [64, 48], 1);
        let r = (v.position - v.look_at).length();
        v.orbit(0.7, 0.3);
        assert!(((v.position - v.look_at).length() - r).abs() < 1e-5 * r);
        assert!(v.position.x.abs() > 0.1, "the yaw turned it about the up axis: {}", v.position);
        assert!(v.position.y > 1.0, "a positive pitch raises it: {}", v.position);
        v.orbit(0.0, 10.0);
        let polar = ((v.position - v.look_at).normalize().dot(Vec3::Y)).acos();
        assert!((polar - POLE_MARGIN).abs() < 1e-3, "clamped at the margin, got {polar}");
    }

    #[test]
    fn fly_moves_camera_and_target_together_or_only_the_selected_light() {
        let mut v = ViewState::of(&file(), [64, 48], 1);
        let (p, t) = (v.position, v.look_at);
        v.fly(Vec3::Z);
        assert!((v.position - p - Vec3::new(0.0, 0.0, -0.2)).length() < 1e-5, "{}", v.position);
        assert!((v.position - p - (v.look_at - t)).length() < 1e-6);
        v.select_next_light();
        assert_eq!(v.selected_light, Some(0));
        let p = v.position;
        v.fly(Vec3::X);
        assert_eq!(v.position, p);
        let mut g = file();
        v.apply(&mut g);
        assert!((g.spotlight[0].position[0] - 0.2).abs() < 1e-5, "{:?}", g.spotlight[0].position);
        v.select_next_light();
        assert_eq!(v.selected_light, None, "one light: the next selection is the camera again");
    }

    #[test]
    fn turning_the_sun_turns_the_directional_lights_and_keeps_their_length() {
        let mut v = ViewState::of(&file(), [64, 48], 1);
        v.sun_turn = [0.0, 90.0];
        let mut g = file();
        v.apply(&mut g);
        let d = Vec3::from(g.directional_light[0].direction);
        assert!((d - Vec3::new(-1.0, -1.0, 0.0)).length() < 1e-5, "{d}");
        v.sun_turn = [-45.0, 0.0];
        let mut g = file();
        v.apply(&mut g);
        let d = Vec3::from(g.directional_light[0].direction);
        assert!((d - Vec3::new(0.0, -2f32.sqrt(), 0.0)).length() < 1e-5, "45 degrees higher: overhead, {d}");
    }

    #[test]
    fn plane_keys_stay_inside_their_limits() {
        let mut v = ViewState::of(&file(), [64, 48], 1);
        for _ in 0..20 {
            v.scale_planes(30, true);
        }
        assert_eq!(v.planes, Some(MAX_PLANES));
        for _ in 0..20 {
            v.scale_planes(30, false);
        }
        assert_eq!(v.planes, Some(MIN_PLANES));
        v.step_subplanes(0, false);
        assert_eq!(v.subplanes, Some(0));
    }

    #[test]
    fn the_printed_camera_reads_back_as_the_same_camera() {
        let mut v = ViewState::of(&file(), [64, 48], 1);
        v.orbit(0.3, 0.2);
        let text = v.camera_toml(&file());
        let back: toml::Table = toml::from_str(&text).expect("TOML");
        let cam: crate::scene::Camera = back["camera"].clone().try_into().expect("a [camera]");
        assert_eq!(Vec3::from(cam.position), v.position);
        assert_eq!(Vec3::from(cam.look_at), v.look_at);
        assert_eq!(cam.vfov_deg, Some(40.0));
    }
}
