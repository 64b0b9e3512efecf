//! Names beside points (a fix's identifier, an airport's code, a city's name): every point
//! of a feature whose style has a `label` gets its text beside its symbol, placed with the
//! same collision rules as the traffic's data blocks ([`crate::labels::LabelPlacer`]: no two
//! overlap, none covers a point's symbol, larger text first, anchors that stay put, fades)
//! and drawn by the shared label shader in two draw calls, without leader lines (as MapLibre
//! draws point names). A label is dropped when its point is behind the planet or the terrain
//! hides it.
//!
//! Text is laid out once per feature (when it is added or changed); per frame each point
//! costs a projection, and a ground lookup for points on the ground.

use globus_geo::{Cartographic, EllipsoidalOccluder};
use globus_vector::{Clamp, Feature};

use crate::labels::LabelRequest;
use crate::labels::gpu::{LabelBatch, LabelDrawer, LabelGpu};
use crate::overlay::FrameContext;
use crate::text::GlyphAtlas;

/// Room round a label's text, pixels.
const PAD_PX: f32 = 2.0;
/// Gap between a point's symbol and its label, pixels.
const GAP_PX: f32 = 3.0;
/// How much nearer than its point the terrain may be before the label goes (fraction of
/// the depth): a point on the ground lies on the drawn surface, give or take the mesh's
/// error.
const TOLERANCE: f32 = 1.0e-3;
/// Fade in and out, seconds.
const FADE_S: f32 = 0.25;
/// Points of one feature that can have labels (ids keep the point's index in 20 bits).
const MAX_POINTS: usize = 1 << 20;

/// One labelled point.
struct Item {
    id: u64,
    lon_deg: f64,
    lat_deg: f64,
    height_m: f64,
    clamp: Clamp,
    colour: u32,
    marker_half_px: f32,
    text_px: f32,
    /// Glyphs (atlas index, top-left from the text's top-left) and the text's size.
    glyphs: Vec<(u16, [f32; 2])>,
    size: [f32; 2],
}

/// The labels of a vector layer; see the module documentation.
#[derive(Default)]
pub(crate) struct PointLabels {
    items: Vec<Item>,
    atlas: Option<GlyphAtlas>,
    batch: LabelBatch,
    drawer: Option<LabelDrawer>,
}

impl PointLabels {
    /// Lays out the labels of `features` (id, feature) again.
    pub(crate) fn rebuild<'a>(&mut self, features: impl Iterator<Item = (u32, &'a Feature)>) {
        self.items.clear();
        let mut features: Vec<_> = features
            .filter(|(_, f)| f.style.label.is_some() && !f.points.is_empty())
            .collect();
        if features.is_empty() {
            return;
        }
        features.sort_unstable_by_key(|(id, _)| *id);
        let atlas = match &mut self.atlas {
            Some(a) => a,
            None => match GlyphAtlas::new() {
                Ok(a) => self.atlas.insert(a),
                Err(e) => {
                    tracing::warn!("point labels are not drawn: {e}");
                    return;
                }
            },
        };
        for (id, f) in features {
            let Some(text) = f.style.label.as_deref() else {
                continue;
            };
            let px = f.style.label_size_px;
            let mut glyphs = Vec::new();
            let size = atlas.layout([text], px, |g, x, y| glyphs.push((g, [x, y])));
            let colour = f.style.label_color.map_or_else(
                || {
                    let [r, g, b, _] = f.style.marker_color.0;
                    let lift = |v: u8| ((u16::from(v) + 255) / 2) as u8;
                    [lift(r), lift(g), lift(b), 255]
                },
                |c| c.0,
            );
            for (k, p) in f.points.iter().enumerate().take(MAX_POINTS) {
                self.items.push(Item {
                    id: (u64::from(id) << 20) | k as u64,
                    lon_deg: p[0],
                    lat_deg: p[1],
                    height_m: p[2],
                    clamp: f.style.clamp,
                    colour: u32::from_le_bytes(colour),
                    marker_half_px: f.style.marker_size_px * 0.5,
                    text_px: px,
                    glyphs: glyphs.clone(),
                    size,
                });
            }
        }
    }

    /// Labels held (one per labelled point).
    pub(crate) fn len(&self) -> usize {
        self.items.len()
    }

    /// Labels drawn in the last frame.
    pub(crate) fn drawn(&self) -> u32 {
        self.batch.placed.len() as u32
    }

    /// The labels drawn in the last frame: (feature id, point index), box on screen (min
    /// x, min y, max x, max y, pixels) and opacity.
    pub(crate) fn drawn_boxes(&self) -> impl Iterator<Item = ((u32, u32), [f32; 4], f32)> + '_ {
        self.batch.placed.iter().map(|p| {
            (
                ((p.id >> 20) as u32, (p.id & 0xf_ffff) as u32),
                p.bounds,
                p.opacity,
            )
        })
    }

    /// Projects this frame's labelled points and claims their markers' boxes.
    pub(crate) fn prepare(&mut self, frame: &FrameContext<'_>) {
        self.batch.begin();
        if self.items.is_empty() {
            self.batch.reset();
            if let Some(d) = &mut self.drawer {
                d.write(frame, 12.0, TOLERANCE, &[], &[]);
            }
            return;
        }
        if self.atlas.is_none() {
            return;
        }
        let camera = frame.camera();
        let view = *camera.view();
        let (w, h) = (f64::from(view.width_px), f64::from(view.height_px));
        let occluder = EllipsoidalOccluder::new(frame.ellipsoid(), view.occlusion_eye());
        for (i, item) in self.items.iter().enumerate() {
            let (lon, lat) = (item.lon_deg.to_radians(), item.lat_deg.to_radians());
            let ground = |frame: &FrameContext<'_>| frame.loaded_ground_m(lon, lat);
            let height = match item.clamp {
                Clamp::Ground => ground(frame),
                Clamp::Absolute => item.height_m,
                Clamp::Relative => ground(frame) + item.height_m,
            };
            let world = frame.world_position(Cartographic::new(lon, lat, height));
            if !occluder.is_point_visible(world) {
                continue;
            }
            let Some((px, depth)) = camera.project_with_depth(world) else {
                continue;
            };
            if !(0.0..=w).contains(&px.x) || !(0.0..=h).contains(&px.y) {
                continue;
            }
            let (x, y, r) = (px.x as f32, px.y as f32, item.marker_half_px);
            let request = LabelRequest {
                id: item.id,
                anchor_px: [x, y],
                clearance_px: r + GAP_PX,
                size_px: [item.size[0] + 2.0 * PAD_PX, item.size[1] + 2.0 * PAD_PX],
                // Larger text first; ties go by id: the order of the features and points.
                priority: item.text_px,
            };
            self.batch.request(
                request,
                i as u32,
                depth as f32,
                [x - r, y - r, x + r, y + r],
            );
        }
        self.batch.claim_symbols(frame);
    }

    /// Places this frame's labels (after every overlay claimed its symbols) and uploads
    /// them.
    pub(crate) fn place(&mut self, frame: &FrameContext<'_>) {
        if self.items.is_empty() {
            return;
        }
        let Some(atlas) = &self.atlas else {
            return;
        };
        self.batch.place(frame, FADE_S);
        let drawer = self
            .drawer
            .get_or_insert_with(|| LabelDrawer::new(frame, atlas, "point labels"));
        let batch = &mut self.batch;
        for k in 0..batch.placed.len() {
            let p = batch.placed[k];
            let (item, depth) = batch.items[p.request];
            let item = &self.items[item as usize];
            let anchor = batch.requests[p.request].anchor_px;
            let row = LabelGpu {
                anchor,
                depth,
                opacity: p.opacity,
                origin: [p.bounds[0], p.bounds[1]],
                size: [p.bounds[2] - p.bounds[0], p.bounds[3] - p.bounds[1]],
                colour: item.colour,
                // No leader line.
                clearance: -1.0,
                scale: drawer.scale_for(item.text_px),
                spare: 0.0,
            };
            batch.push_row(row, &item.glyphs, PAD_PX);
        }
        drawer.write(frame, 12.0, TOLERANCE, &batch.rows, &batch.glyphs);
    }

    /// Draw calls of this frame's labels.
    pub(crate) fn draw_calls(&self) -> u32 {
        self.drawer.as_ref().map_or(0, LabelDrawer::draw_calls)
    }

    /// GPU bytes held.
    pub(crate) fn gpu_bytes(&self) -> u64 {
        self.drawer.as_ref().map_or(0, LabelDrawer::gpu_bytes)
    }

    /// Draws them (screen-aligned pass).
    pub(crate) fn draw(&self, pass: &mut wgpu::RenderPass<'_>) {
        if let Some(d) = &self.drawer {
            d.draw(pass);
        }
    }
}
