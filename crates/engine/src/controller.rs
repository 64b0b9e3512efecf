//! [`CameraController`]: globe camera controls (Kaiser 2018, 4.4) as methods that take pixel
//! positions and deltas, so a window, an embedding program or a test drives them alike.
//!
//! * **Pan**: the grabbed ground point stays under the cursor. The camera turns about the
//!   body's centre by the rotation that brings the point under the cursor back to the
//!   grabbed one, on the sphere through the grabbed point (Kaiser 4.4.1): from orbit this is
//!   a rotation of the globe, close to the ground a drag over it.
//! * **Zoom**: along the ray through the cursor (the point under it stays there), by a
//!   fraction of the height above the ground per notch, stopping short of the ground.
//! * **Look around**: turn about the local vertical and tilt about the camera's right axis
//!   where the camera stands (4.4.3), never past straight up or down.
//! * **Inspection point**: orbit about a picked ground point (4.4.4): horizontally about the
//!   point's vertical, vertically about the camera's right axis, clamped so that the camera
//!   stays between just above the point's horizon and just short of straight above it
//!   (never flipping over) and above the ground everywhere.
//! * **Fly-to**: a smooth flight to a target view over a given duration, rising with the
//!   distance to cover, ending exactly at the target.
//! * **Orthographic top-down** (Kaiser 2.4.3 and 5.7.2, the ATC screen):
//!   [`CameraController::set_orthographic`] looks straight down on the point at the centre
//!   of the screen with a parallel projection of the same scale there. Zoom then changes the
//!   projection's size about the cursor, pan moves the eye (the grabbed point stays under the
//!   cursor, as in perspective), look and orbit only turn about the vertical; the eye stays
//!   [`ORTHO_EYE_HEIGHT_M`] above the ellipsoid, over anything that flies.
//!
//! What the camera stands on comes through [`Ground`], which [`crate::Globe`] implements
//! with its loaded terrain; tests can implement it with an analytic surface.

use std::time::Duration;

use glam::DVec2;
use globus_geo::{Cartographic, DQuat, DVec3, Ellipsoid, View};

use crate::Globe;

/// The surface the camera moves over.
pub trait Ground {
    /// The body.
    fn ellipsoid(&self) -> Ellipsoid;
    /// Height of the drawn ground (with any exaggeration) above the ellipsoid at a longitude
    /// and latitude (radians), metres.
    fn drawn_ground_m(&self, lon_rad: f64, lat_rad: f64) -> f64;
    /// The first point where a ray meets the drawn ground.
    fn ray_pick(&self, origin: DVec3, direction: DVec3) -> Option<DVec3>;
}

impl Ground for Globe {
    fn ellipsoid(&self) -> Ellipsoid {
        Globe::ellipsoid(self)
    }

    fn drawn_ground_m(&self, lon_rad: f64, lat_rad: f64) -> f64 {
        Globe::drawn_ground_m(self, lon_rad, lat_rad)
    }

    fn ray_pick(&self, origin: DVec3, direction: DVec3) -> Option<DVec3> {
        Globe::ray_pick(self, origin, direction)
    }
}

/// The bare ellipsoid as ground (for programs without terrain, and tests).
impl Ground for Ellipsoid {
    fn ellipsoid(&self) -> Ellipsoid {
        *self
    }

    fn drawn_ground_m(&self, _lon_rad: f64, _lat_rad: f64) -> f64 {
        0.0
    }

    fn ray_pick(&self, origin: DVec3, direction: DVec3) -> Option<DVec3> {
        self.ray_hit(origin, direction.try_normalize()?)
    }
}

/// Fraction of the height above the ground one zoom notch moves in.
const ZOOM_IN_PER_NOTCH: f64 = 0.2;
/// ... and out.
const ZOOM_OUT_PER_NOTCH: f64 = 0.25;
/// The camera never comes further from the centre than this, metres.
const MAX_DISTANCE_M: f64 = 1.0e8;
/// Inspection orbits keep the camera between these elevations above the pivot's horizon.
const MIN_ORBIT_ELEVATION_RAD: f64 = 0.5 * std::f64::consts::PI / 180.0;
const MAX_ORBIT_ELEVATION_RAD: f64 = 89.5 * std::f64::consts::PI / 180.0;
/// Height of an orthographic camera's eye above the ellipsoid, metres: above everything
/// drawn on Earth (the highest ground is 8.8 km, airliners fly below 15 km, balloons below
/// 50 km), and low enough that depth stays fine over the near side.
pub const ORTHO_EYE_HEIGHT_M: f64 = 100_000.0;
/// Smallest and largest orthographic view heights, metres.
const ORTHO_MIN_HEIGHT_M: f64 = 10.0;
const ORTHO_MAX_HEIGHT_M: f64 = 4.0e7;
/// Look-around never tilts closer than this to straight up or down.
const MAX_LOOK_PITCH_RAD: f64 = 87.5 * std::f64::consts::PI / 180.0;

#[derive(Clone, Copy, Debug)]
struct Grab {
    point: DVec3,
    radius: f64,
    /// The camera when the point was grabbed: every pan position is a rotation of it, so a
    /// drag that comes back to where it started puts the camera back where it was.
    start: View,
}

#[derive(Clone, Copy, Debug)]
struct Flight {
    from: View,
    to: View,
    from_c: Cartographic,
    to_c: Cartographic,
    /// Headings and pitches at both ends, radians.
    from_hp: (f64, f64),
    to_hp: (f64, f64),
    peak_m: f64,
    duration_s: f64,
    elapsed_s: f64,
}

/// Camera controls over a [`Ground`]; see the module documentation.
#[derive(Clone, Debug)]
pub struct CameraController {
    view: View,
    grab: Option<Grab>,
    orbit: Option<DVec3>,
    flight: Option<Flight>,
    clearance_m: f64,
}

impl CameraController {
    /// Controls starting at `view`, keeping the eye at least 1 m above the ground.
    pub fn new(view: View) -> Self {
        Self {
            view,
            grab: None,
            orbit: None,
            flight: None,
            clearance_m: 1.0,
        }
    }

    /// The camera now.
    pub fn view(&self) -> &View {
        &self.view
    }

    /// Puts the camera somewhere else (ends any flight, drag or orbit).
    pub fn set_view(&mut self, view: View) {
        self.view = view;
        self.grab = None;
        self.orbit = None;
        self.flight = None;
    }

    /// The least height above the ground the camera keeps, metres (default 1).
    pub fn set_clearance_m(&mut self, metres: f64) {
        self.clearance_m = metres.max(0.0);
    }

    /// A new viewport size, pixels.
    pub fn resize(&mut self, width_px: u32, height_px: u32) {
        self.view.width_px = width_px.max(1);
        self.view.height_px = height_px.max(1);
    }

    /// Height of the eye above the drawn ground, metres.
    pub fn height_above_ground_m(&self, ground: &impl Ground) -> f64 {
        let e = ground.ellipsoid();
        e.ecef_to_cartographic(self.view.position).map_or(0.0, |c| {
            c.height_m - ground.drawn_ground_m(c.lon_rad, c.lat_rad)
        })
    }

    /// The ground point under a pixel (terrain, else the ellipsoid).
    pub fn ground_under(&self, ground: &impl Ground, x_px: f64, y_px: f64) -> Option<DVec3> {
        let (origin, dir) = self.view.ray(x_px, y_px);
        ground
            .ray_pick(origin, dir)
            .or_else(|| ground.ellipsoid().ray_hit(origin, dir))
    }

    /// Grabs the ground under the cursor; false (and nothing grabbed) over the sky.
    pub fn begin_pan(&mut self, ground: &impl Ground, x_px: f64, y_px: f64) -> bool {
        self.flight = None;
        self.grab = self.ground_under(ground, x_px, y_px).map(|point| Grab {
            point,
            radius: point.length(),
            start: self.view,
        });
        self.grab.is_some()
    }

    /// Moves the camera so the grabbed point is under the cursor at (`x_px`, `y_px`): the
    /// camera at the grab turned about the centre by the rotation that takes the point its
    /// ray through the cursor meets on the grabbed point's sphere to the grabbed point (the
    /// rotated ray then meets the grabbed point). Where that ray misses the sphere (the cursor
    /// beyond the horizon the camera had) the camera stays.
    pub fn pan_to(&mut self, ground: &impl Ground, x_px: f64, y_px: f64) {
        let Some(grab) = self.grab else {
            return;
        };
        let start = View {
            width_px: self.view.width_px,
            height_px: self.view.height_px,
            ..grab.start
        };
        let (origin, dir) = start.ray(x_px, y_px);
        let Some((t, _)) = Ellipsoid::sphere(grab.radius).intersect_ray(origin, dir) else {
            return;
        };
        if t <= 0.0 {
            return;
        }
        let under_cursor = origin + dir * t;
        let (Some(from), Some(to)) = (under_cursor.try_normalize(), grab.point.try_normalize())
        else {
            return;
        };
        let q = DQuat::from_rotation_arc(from, to);
        self.view.position = q * start.position;
        self.view.orientation = (q * start.orientation).normalize();
        self.settle_orthographic_eye(&ground.ellipsoid());
        self.keep_above_ground(ground);
    }

    /// Lets go of the grabbed point.
    pub fn end_pan(&mut self) {
        self.grab = None;
    }

    /// Zooms towards (positive `notches`) or away from the point under the cursor, by a
    /// fifth (a quarter, out) of the height above the ground per notch, at most five notches
    /// at once. The point stays under the cursor; the eye stops short of the ground.
    pub fn zoom(&mut self, ground: &impl Ground, x_px: f64, y_px: f64, notches: f64) {
        if notches == 0.0 || !notches.is_finite() {
            return;
        }
        self.flight = None;
        if let Some(height_m) = self.view.ortho_height_m() {
            self.zoom_orthographic(ground, x_px, y_px, notches, height_m);
            return;
        }
        let h = self.height_above_ground_m(ground).max(self.clearance_m);
        let dir = self.view.ray_direction(x_px, y_px);
        let target = ground.ray_pick(self.view.position, dir);
        let mut step = if notches > 0.0 {
            ZOOM_IN_PER_NOTCH * h * notches.min(5.0)
        } else {
            -ZOOM_OUT_PER_NOTCH * h * (-notches).min(5.0)
        };
        if let Some(t) = target {
            // Never past the target: stop the clearance short of it.
            step = step.min((t - self.view.position).length() - self.clearance_m);
        }
        let start = self.view.position;
        let fits = |s: f64| {
            let p = start + dir * s;
            p.length() <= MAX_DISTANCE_M && self.clear_of_ground(ground, p)
        };
        // The longest part of the step that keeps the eye clear of the ground.
        let mut allowed = step;
        if !fits(allowed) {
            let (mut ok, mut bad) = (0.0, step);
            for _ in 0..30 {
                let m = 0.5 * (ok + bad);
                if fits(m) {
                    ok = m;
                } else {
                    bad = m;
                }
            }
            allowed = ok;
        }
        self.view.position = start + dir * allowed;
    }

    /// Orthographic zoom: the projection's size by the same fractions per notch, the point
    /// under the cursor kept there (the eye turned about the centre to bring it back).
    fn zoom_orthographic(
        &mut self,
        ground: &impl Ground,
        x_px: f64,
        y_px: f64,
        notches: f64,
        height_m: f64,
    ) {
        let factor = if notches > 0.0 {
            (1.0 - ZOOM_IN_PER_NOTCH).powf(notches.min(5.0))
        } else {
            (1.0 + ZOOM_OUT_PER_NOTCH).powf((-notches).min(5.0))
        };
        let before = self.ground_under(ground, x_px, y_px);
        self.view = self
            .view
            .orthographic((height_m * factor).clamp(ORTHO_MIN_HEIGHT_M, ORTHO_MAX_HEIGHT_M));
        let Some(b) = before else {
            return;
        };
        // Where the new ray meets the sphere through the point (as pan does): the turn that
        // takes it there puts the ray through the point itself.
        let (origin, dir) = self.view.ray(x_px, y_px);
        let after = Ellipsoid::sphere(b.length())
            .intersect_ray(origin, dir)
            .map(|(t, _)| origin + dir * t);
        if let Some(a) = after
            && let (Some(from), Some(to)) = (a.try_normalize(), b.try_normalize())
        {
            let q = DQuat::from_rotation_arc(from, to);
            self.view.position = q * self.view.position;
            self.view.orientation = (q * self.view.orientation).normalize();
        }
        self.settle_orthographic_eye(&ground.ellipsoid());
    }

    /// Slides an orthographic eye along its view axis (which changes nothing on the screen)
    /// back to [`ORTHO_EYE_HEIGHT_M`] above the ellipsoid: turns about the centre move it up
    /// or down with the ellipsoid's flattening.
    fn settle_orthographic_eye(&mut self, e: &Ellipsoid) {
        if !self.is_orthographic() {
            return;
        }
        let forward = self.view.forward();
        for _ in 0..3 {
            let Some(c) = e.ecef_to_cartographic(self.view.position) else {
                return;
            };
            let up = e.geodetic_normal(self.view.position).unwrap_or(DVec3::Z);
            let cos = (-forward.dot(up)).max(0.1);
            self.view.position += forward * ((c.height_m - ORTHO_EYE_HEIGHT_M) / cos);
        }
    }

    /// Whether the camera is the orthographic top-down one.
    pub fn is_orthographic(&self) -> bool {
        self.view.ortho_height_m().is_some()
    }

    /// Switches between the perspective camera and the orthographic top-down one (see the
    /// module documentation), about the ground at the centre of the screen (the point under
    /// the eye when the centre shows sky), keeping the heading and the scale there. Back in
    /// perspective the camera looks straight down from the height that shows the same.
    pub fn set_orthographic(&mut self, ground: &impl Ground, on: bool) {
        if on == self.is_orthographic() {
            return;
        }
        self.flight = None;
        self.grab = None;
        self.orbit = None;
        let e = ground.ellipsoid();
        let (w, h) = (
            f64::from(self.view.width_px),
            f64::from(self.view.height_px),
        );
        let centre = self.ground_under(ground, 0.5 * w, 0.5 * h).or_else(|| {
            let c = e.ecef_to_cartographic(self.view.position)?;
            Some(e.cartographic_to_ecef(Cartographic::new(c.lon_rad, c.lat_rad, 0.0)))
        });
        let Some(target) = centre.and_then(|p| e.ecef_to_cartographic(p)) else {
            return;
        };
        let heading = self.view.heading_pitch(&e).map_or(0.0, |(h, _)| h);
        let fov = self.view.fov_y_rad;
        let tan = (0.5 * fov).tan();
        let down = -std::f64::consts::FRAC_PI_2;
        let at = |height_m: f64| Cartographic::new(target.lon_rad, target.lat_rad, height_m);
        let view = |height_m: f64| {
            View::from_geodetic(
                &e,
                at(height_m),
                heading,
                down,
                fov,
                self.view.width_px,
                self.view.height_px,
            )
        };
        let ground_m = ground.drawn_ground_m(target.lon_rad, target.lat_rad);
        if on {
            let distance = (self.view.position - e.cartographic_to_ecef(target)).length();
            let size = (2.0 * tan * distance).clamp(ORTHO_MIN_HEIGHT_M, ORTHO_MAX_HEIGHT_M);
            self.view = view(ORTHO_EYE_HEIGHT_M.max(ground_m + 1_000.0)).orthographic(size);
        } else {
            let size = self.view.ortho_height_m().unwrap_or(1e6);
            let above = (0.5 * size / tan).max(self.clearance_m);
            self.view = view(ground_m + above);
            self.keep_above_ground(ground);
        }
    }

    /// Turns (`dx_px`) and tilts (`dy_px`) the camera where it stands, by the angle the
    /// cursor moved across the field of view (an orthographic camera only turns).
    pub fn look(&mut self, ground: &impl Ground, dx_px: f64, dy_px: f64) {
        self.flight = None;
        let per_px = self.view.fov_y_rad / f64::from(self.view.height_px.max(1));
        let up = ground
            .ellipsoid()
            .geodetic_normal(self.view.position)
            .unwrap_or(DVec3::Z);
        let turn = DQuat::from_axis_angle(up, -dx_px * per_px);
        // Tilt, stopping short of straight up or down.
        let pitch = self.view.forward().dot(up).clamp(-1.0, 1.0).asin();
        let limit = MAX_LOOK_PITCH_RAD;
        // (Never further past the limit than the camera already is.)
        let tilt = if self.is_orthographic() {
            0.0
        } else {
            (pitch - dy_px * per_px).clamp((-limit).min(pitch), limit.max(pitch)) - pitch
        };
        let tilt = DQuat::from_axis_angle(self.view.right(), tilt);
        self.view.orientation = (turn * tilt * self.view.orientation).normalize();
    }

    /// Picks the ground point under the cursor as the inspection point to orbit about;
    /// false over the sky.
    pub fn begin_orbit(&mut self, ground: &impl Ground, x_px: f64, y_px: f64) -> bool {
        self.flight = None;
        self.orbit = self.ground_under(ground, x_px, y_px);
        self.orbit.is_some()
    }

    /// Orbits about the inspection point: `dx_px` about its vertical (the view turns with the
    /// cursor), `dy_px` about the camera's right axis (`radians_per_px` each; dragging down
    /// raises the camera over the point, up lowers it towards the horizon), clamped (see the
    /// module documentation). The inspection point keeps its place on the screen.
    pub fn orbit_by(&mut self, ground: &impl Ground, dx_px: f64, dy_px: f64, radians_per_px: f64) {
        let Some(pivot) = self.orbit else {
            return;
        };
        let e = ground.ellipsoid();
        let up = e.geodetic_normal(pivot).unwrap_or(DVec3::Z);
        let about_pivot = |view: &View, q: DQuat| View {
            position: pivot + q * (view.position - pivot),
            orientation: (q * view.orientation).normalize(),
            ..*view
        };
        // Horizontally about the point's vertical (Kaiser 4.4.4 turns about the direction
        // from the centre, which differs from the vertical by up to 0.19 degrees on WGS84 and
        // would move the camera's elevation as it turns).
        let turned = about_pivot(
            &self.view,
            DQuat::from_axis_angle(up, -dx_px * radians_per_px),
        );
        if self.orbit_allowed(ground, &turned, pivot, up) {
            self.view = turned;
        }
        if self.is_orthographic() {
            // Straight down it stays.
            return;
        }
        // Vertically: the largest part of the rotation that stays within the clamps.
        let angle = -dy_px * radians_per_px;
        let right = self.view.right();
        let tilted = |f: f64| about_pivot(&self.view, DQuat::from_axis_angle(right, angle * f));
        if self.orbit_allowed(ground, &tilted(1.0), pivot, up) {
            self.view = tilted(1.0);
            return;
        }
        let (mut ok, mut bad) = (0.0, 1.0);
        for _ in 0..30 {
            let m = 0.5 * (ok + bad);
            if self.orbit_allowed(ground, &tilted(m), pivot, up) {
                ok = m;
            } else {
                bad = m;
            }
        }
        self.view = tilted(ok);
    }

    /// Whether an orbit may put the camera at `view`: its elevation above the pivot's
    /// horizon within the clamps, upright (its up vector on the pivot's sky side), and clear
    /// of the ground.
    fn orbit_allowed(&self, ground: &impl Ground, view: &View, pivot: DVec3, up: DVec3) -> bool {
        let Some(to_eye) = (view.position - pivot).try_normalize() else {
            return false;
        };
        let elevation = to_eye.dot(up).clamp(-1.0, 1.0).asin();
        (MIN_ORBIT_ELEVATION_RAD..=MAX_ORBIT_ELEVATION_RAD).contains(&elevation)
            && view.up().dot(up) > 0.0
            && self.clear_of_ground(ground, view.position)
    }

    /// Ends the orbit.
    pub fn end_orbit(&mut self) {
        self.orbit = None;
    }

    /// Starts a flight to `target` lasting `duration`, along the great circle, rising with
    /// the distance covered (to 40 % of it, never above 20,000 km), easing in and out.
    /// [`CameraController::update`] advances it.
    pub fn fly_to(&mut self, ground: &impl Ground, target: View, duration: Duration) {
        let e = ground.ellipsoid();
        let (Some(from_c), Some(to_c)) = (
            e.ecef_to_cartographic(self.view.position),
            e.ecef_to_cartographic(target.position),
        ) else {
            self.set_view(target);
            return;
        };
        let hp = |v: &View| {
            v.heading_pitch(&e)
                .unwrap_or((0.0, -std::f64::consts::FRAC_PI_2))
        };
        let distance = e.great_circle_distance(from_c, to_c);
        let peak_m = from_c
            .height_m
            .max(to_c.height_m)
            .max((0.4 * distance).min(2.0e7));
        self.grab = None;
        self.orbit = None;
        self.flight = Some(Flight {
            from: self.view,
            to: View {
                width_px: self.view.width_px,
                height_px: self.view.height_px,
                ..target
            },
            from_c,
            to_c,
            from_hp: hp(&self.view),
            to_hp: hp(&target),
            peak_m,
            duration_s: duration.as_secs_f64(),
            elapsed_s: 0.0,
        });
    }

    /// Whether a flight is under way.
    pub fn is_flying(&self) -> bool {
        self.flight.is_some()
    }

    /// Advances a flight by `dt`; at its end the camera is exactly the target. Returns
    /// whether the camera moved.
    pub fn update(&mut self, ground: &impl Ground, dt: Duration) -> bool {
        let Some(mut f) = self.flight else {
            return false;
        };
        f.elapsed_s += dt.as_secs_f64();
        if f.elapsed_s >= f.duration_s {
            self.view = f.to;
            self.flight = None;
            return true;
        }
        let t = (f.elapsed_s / f.duration_s).clamp(0.0, 1.0);
        let s = t * t * (3.0 - 2.0 * t);
        self.view = flight_view(&ground.ellipsoid(), &f, s);
        self.flight = Some(f);
        self.keep_above_ground(ground);
        true
    }

    /// Flies the camera along its own axes (`forward` along the view projected onto the
    /// ground, `right`, `up` along the vertical; each -1..1) for `dt`, at 1.5 times the height
    /// above the ground per second, carrying its orientation along the curve of the planet.
    pub fn fly(&mut self, ground: &impl Ground, forward: f64, right: f64, up: f64, dt: Duration) {
        let dt = dt.as_secs_f64().min(0.1);
        if dt == 0.0 || (forward == 0.0 && right == 0.0 && up == 0.0) {
            return;
        }
        self.flight = None;
        // Orthographic: half the view's height per second.
        let speed = self.view.ortho_height_m().map_or_else(
            || self.height_above_ground_m(ground).max(self.clearance_m) * 1.5,
            |h| h * 0.5,
        );
        let e = ground.ellipsoid();
        let vertical = e.geodetic_normal(self.view.position).unwrap_or(DVec3::Z);
        let ahead = (self.view.forward() - vertical * self.view.forward().dot(vertical))
            .normalize_or(self.view.up());
        let side = ahead.cross(vertical);
        let v = ahead * forward + side * right + vertical * up;
        self.move_by(ground, v * speed * dt);
    }

    /// Moves the eye, keeping it clear of the ground and within 100,000 km, and turns the
    /// orientation with the local vertical.
    fn move_by(&mut self, ground: &impl Ground, delta: DVec3) {
        let e = ground.ellipsoid();
        let Some(mut c) = e.ecef_to_cartographic(self.view.position + delta) else {
            return;
        };
        let floor = ground.drawn_ground_m(c.lon_rad, c.lat_rad) + self.clearance_m;
        c.height_m = c.height_m.clamp(floor, MAX_DISTANCE_M);
        let old_up = e.geodetic_normal(self.view.position).unwrap_or(DVec3::Z);
        self.view.position = e.cartographic_to_ecef(c);
        let new_up = e.geodetic_normal(self.view.position).unwrap_or(DVec3::Z);
        let q = DQuat::from_rotation_arc(old_up, new_up);
        self.view.orientation = (q * self.view.orientation).normalize();
    }

    /// Whether a position is at least the clearance above the drawn ground.
    fn clear_of_ground(&self, ground: &impl Ground, p: DVec3) -> bool {
        ground.ellipsoid().ecef_to_cartographic(p).is_some_and(|c| {
            c.height_m >= ground.drawn_ground_m(c.lon_rad, c.lat_rad) + self.clearance_m - 1e-6
        })
    }

    /// Raises the eye to the clearance above the ground if it is below.
    fn keep_above_ground(&mut self, ground: &impl Ground) {
        let e = ground.ellipsoid();
        if let Some(mut c) = e.ecef_to_cartographic(self.view.position) {
            let floor = ground.drawn_ground_m(c.lon_rad, c.lat_rad) + self.clearance_m;
            if c.height_m < floor {
                c.height_m = floor;
                self.view.position = e.cartographic_to_ecef(c);
            }
        }
    }

    /// The pixel a world point is seen at, for callers that track one.
    pub fn project(&self, world: DVec3) -> Option<DVec2> {
        self.view.project(world).map(|(x, y)| DVec2::new(x, y))
    }
}

/// The camera `s` (0..1, eased) of the way along a flight.
fn flight_view(e: &Ellipsoid, f: &Flight, s: f64) -> View {
    let (a, b) = (f.from_c, f.to_c);
    // The surface point along the great circle (slerp of the directions from the centre).
    let na = e.geodetic_normal_from_lon_lat(a.lon_rad, a.lat_rad);
    let nb = e.geodetic_normal_from_lon_lat(b.lon_rad, b.lat_rad);
    let angle = na.dot(nb).clamp(-1.0, 1.0).acos();
    let dir = if angle < 1e-9 {
        na
    } else {
        let axis = na.cross(nb).try_normalize().unwrap_or(DVec3::Z);
        DQuat::from_axis_angle(axis, angle * s) * na
    };
    let lon = dir.y.atan2(dir.x);
    let lat = dir.z.clamp(-1.0, 1.0).asin();
    // Height: a quadratic Bezier from one end's to the other's through the peak at s = 0.5.
    let control = 2.0 * f.peak_m - 0.5 * (a.height_m + b.height_m);
    let h = (1.0 - s).powi(2) * a.height_m + 2.0 * s * (1.0 - s) * control + s * s * b.height_m;
    let mut dh = f.to_hp.0 - f.from_hp.0;
    dh = (dh + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI) - std::f64::consts::PI;
    let heading = f.from_hp.0 + dh * s;
    let pitch = f.from_hp.1 + (f.to_hp.1 - f.from_hp.1) * s;
    let view = View::from_geodetic(
        e,
        Cartographic::new(lon, lat, h),
        heading,
        pitch,
        f.from.fov_y_rad + (f.to.fov_y_rad - f.from.fov_y_rad) * s,
        f.from.width_px,
        f.from.height_px,
    );
    // Between orthographic views the projection's size changes geometrically.
    match (f.from.ortho_height_m(), f.to.ortho_height_m()) {
        (Some(a), Some(b)) => view.orthographic(a * (b / a).powf(s)),
        _ => view,
    }
}
