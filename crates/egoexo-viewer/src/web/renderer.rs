//! The wgpu renderer: pipelines for instanced spheres and cylinders (opaque and translucent) and
//! for world lines, drawing one [`FrameDrawList`] plus the static lines into a colour target,
//! 4× multisampled where the format allows.

use wgpu::util::DeviceExt;

use crate::camera::ViewPoint;
use crate::colors;
use crate::mesh::{self, LineVertex, MeshVertex};
use crate::scene::{FrameDrawList, SolidInstance};

const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth24Plus;

/// The joints' and bones' tessellation: 256 triangles a sphere, 12 sides a cylinder — a joint
/// is 5–40 px across in the views the viewer frames, where these read as round. Every sphere
/// and bone of every body is drawn once or twice (translucent ones with a depth pass), so their
/// triangles are most of a frame's work where the GPU is the CPU (SwiftShader: 14 × 24 spheres
/// and 24 sides cost 0.8–0.9 s of CPU a draw with 4× MSAA at 944 × 570, 6 × 10 and 8 sides 0.26–
/// 0.31 s; docs/performance.md).
const SPHERE_RINGS: u16 = 8;
const SPHERE_SEGMENTS: u16 = 16;
const CYLINDER_SEGMENTS: u16 = 12;

/// Uniforms shared by every pipeline (layout of `Globals` in `viewer.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Globals {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    params: [f32; 4],
}

struct GpuMesh {
    vertices: wgpu::Buffer,
    indices: wgpu::Buffer,
    index_count: u32,
}

impl GpuMesh {
    fn new(device: &wgpu::Device, mesh: &mesh::Mesh, label: &str) -> Self {
        let vertices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(&mesh.vertices),
            usage: wgpu::BufferUsages::VERTEX,
        });
        // Index buffers must be a multiple of 4 bytes long; u16 indices may need a pad.
        let mut indices = mesh.indices.clone();
        if indices.len() % 2 == 1 {
            indices.push(0);
        }
        let indices = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents: bytemuck::cast_slice(&indices),
            usage: wgpu::BufferUsages::INDEX,
        });
        Self { vertices, indices, index_count: mesh.indices.len() as u32 }
    }
}

/// A vertex buffer that grows (doubling) to fit what is written into it.
struct GrowableBuffer {
    buffer: wgpu::Buffer,
    capacity: u64,
    label: &'static str,
}

impl GrowableBuffer {
    fn new(device: &wgpu::Device, label: &'static str) -> Self {
        let capacity = 64 * 1024;
        Self { buffer: Self::allocate(device, label, capacity), capacity, label }
    }

    fn allocate(device: &wgpu::Device, label: &str, size: u64) -> wgpu::Buffer {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    fn write(&mut self, device: &wgpu::Device, queue: &wgpu::Queue, bytes: &[u8]) {
        let needed = (bytes.len() as u64).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        if needed > self.capacity {
            self.capacity = needed.next_power_of_two();
            self.buffer = Self::allocate(device, self.label, self.capacity);
        }
        if !bytes.is_empty() {
            let mut padded;
            let data = if bytes.len() as u64 == needed {
                bytes
            } else {
                padded = bytes.to_vec();
                padded.resize(needed as usize, 0);
                &padded
            };
            queue.write_buffer(&self.buffer, 0, data);
        }
    }
}

/// Attachments that depend on the target size.
struct SizedTargets {
    size: (u32, u32),
    msaa: Option<wgpu::TextureView>,
    depth: wgpu::TextureView,
}

struct Pipelines {
    spheres: wgpu::RenderPipeline,
    cylinders: wgpu::RenderPipeline,
    /// Depth only (no colour): the translucent solids' pre-pass.
    depth_spheres: wgpu::RenderPipeline,
    depth_cylinders: wgpu::RenderPipeline,
    translucent_spheres: wgpu::RenderPipeline,
    translucent_cylinders: wgpu::RenderPipeline,
    lines: wgpu::RenderPipeline,
}

/// How a pipeline treats depth and colour.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Pass {
    /// Writes depth and colour.
    Opaque,
    /// Writes depth only.
    DepthOnly,
    /// Tests depth, blends colour.
    Translucent,
}

/// Draws the viewer's scene into textures of one colour format.
pub(crate) struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    format: wgpu::TextureFormat,
    sample_count: u32,
    globals: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
    pipelines: Pipelines,
    sphere: GpuMesh,
    cylinder: GpuMesh,
    instances: GrowableBuffer,
    lines: GrowableBuffer,
    line_vertex_count: u32,
    targets: Option<SizedTargets>,
}

impl std::fmt::Debug for Renderer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Renderer").field("format", &self.format).field("sample_count", &self.sample_count).finish()
    }
}

impl Renderer {
    /// A renderer for colour targets of `format`; `msaa_supported` says whether the adapter can
    /// multisample that format 4×.
    pub(crate) fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        format: wgpu::TextureFormat,
        msaa_supported: bool,
    ) -> Self {
        let sample_count = if msaa_supported { 4 } else { 1 };
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("egoexo viewer shaders"),
            source: wgpu::ShaderSource::Wgsl(include_str!("viewer.wgsl").into()),
        });
        let globals = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("globals"),
            size: std::mem::size_of::<Globals>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("globals"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("globals"),
            layout: &bind_group_layout,
            entries: &[wgpu::BindGroupEntry { binding: 0, resource: globals.as_entire_binding() }],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("viewer"),
            bind_group_layouts: &[Some(&bind_group_layout)],
            immediate_size: 0,
        });

        let mesh_attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3];
        let instance_attributes = wgpu::vertex_attr_array![
            2 => Float32x3, 3 => Float32, 4 => Float32x3, 6 => Float32, 5 => Float32x4
        ];
        let solid_buffers = [
            Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<MeshVertex>() as u64,
                step_mode: wgpu::VertexStepMode::Vertex,
                attributes: &mesh_attributes,
            }),
            Some(wgpu::VertexBufferLayout {
                array_stride: std::mem::size_of::<SolidInstance>() as u64,
                step_mode: wgpu::VertexStepMode::Instance,
                attributes: &instance_attributes,
            }),
        ];
        let line_attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x4];
        let line_buffers = [Some(wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<LineVertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &line_attributes,
        })];
        let blend = wgpu::BlendState {
            color: wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::SrcAlpha,
                dst_factor: wgpu::BlendFactor::OneMinusSrcAlpha,
                operation: wgpu::BlendOperation::Add,
            },
            alpha: wgpu::BlendComponent {
                src_factor: wgpu::BlendFactor::One,
                dst_factor: wgpu::BlendFactor::OneMinusSrcAlpha,
                operation: wgpu::BlendOperation::Add,
            },
        };
        let pipeline = |label: &str,
                        vertex_entry: &str,
                        fragment_entry: &str,
                        buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
                        topology: wgpu::PrimitiveTopology,
                        pass: Pass| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &shader,
                    entry_point: Some(vertex_entry),
                    compilation_options: Default::default(),
                    buffers,
                },
                primitive: wgpu::PrimitiveState {
                    topology,
                    front_face: wgpu::FrontFace::Ccw,
                    cull_mode: (topology == wgpu::PrimitiveTopology::TriangleList).then_some(wgpu::Face::Back),
                    ..Default::default()
                },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: DEPTH_FORMAT,
                    depth_write_enabled: Some(pass != Pass::Translucent),
                    depth_compare: Some(wgpu::CompareFunction::LessEqual),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: wgpu::MultisampleState { count: sample_count, ..Default::default() },
                fragment: Some(wgpu::FragmentState {
                    module: &shader,
                    entry_point: Some(fragment_entry),
                    compilation_options: Default::default(),
                    targets: &[Some(wgpu::ColorTargetState {
                        format,
                        blend: (pass == Pass::Translucent).then_some(blend),
                        write_mask: if pass == Pass::DepthOnly {
                            wgpu::ColorWrites::empty()
                        } else {
                            wgpu::ColorWrites::ALL
                        },
                    })],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let triangles = wgpu::PrimitiveTopology::TriangleList;
        let pipelines = Pipelines {
            spheres: pipeline("spheres", "vs_sphere", "fs_solid", &solid_buffers, triangles, Pass::Opaque),
            cylinders: pipeline("cylinders", "vs_cylinder", "fs_solid", &solid_buffers, triangles, Pass::Opaque),
            depth_spheres: pipeline(
                "depth spheres",
                "vs_sphere",
                "fs_solid",
                &solid_buffers,
                triangles,
                Pass::DepthOnly,
            ),
            depth_cylinders: pipeline(
                "depth cylinders",
                "vs_cylinder",
                "fs_solid",
                &solid_buffers,
                triangles,
                Pass::DepthOnly,
            ),
            translucent_spheres: pipeline(
                "translucent spheres",
                "vs_sphere",
                "fs_solid",
                &solid_buffers,
                triangles,
                Pass::Translucent,
            ),
            translucent_cylinders: pipeline(
                "translucent cylinders",
                "vs_cylinder",
                "fs_solid",
                &solid_buffers,
                triangles,
                Pass::Translucent,
            ),
            lines: pipeline(
                "lines",
                "vs_line",
                "fs_line",
                &line_buffers,
                wgpu::PrimitiveTopology::LineList,
                Pass::Translucent,
            ),
        };

        Self {
            device: device.clone(),
            queue: queue.clone(),
            format,
            sample_count,
            globals,
            bind_group,
            pipelines,
            sphere: GpuMesh::new(device, &mesh::unit_sphere(SPHERE_RINGS, SPHERE_SEGMENTS), "sphere"),
            cylinder: GpuMesh::new(device, &mesh::unit_cylinder(CYLINDER_SEGMENTS), "cylinder"),
            instances: GrowableBuffer::new(device, "instances"),
            lines: GrowableBuffer::new(device, "lines"),
            line_vertex_count: 0,
            targets: None,
        }
    }

    /// Replaces the static lines (grid, whole trajectories).
    pub(crate) fn set_static_lines(&mut self, lines: &[LineVertex]) {
        self.lines.write(&self.device, &self.queue, bytemuck::cast_slice(lines));
        self.line_vertex_count = lines.len() as u32;
    }

    fn create_targets(&self, size: (u32, u32)) -> SizedTargets {
        let extent = wgpu::Extent3d { width: size.0, height: size.1, depth_or_array_layers: 1 };
        let texture = |label: &str, format: wgpu::TextureFormat| {
            self.device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: extent,
                    mip_level_count: 1,
                    sample_count: self.sample_count,
                    dimension: wgpu::TextureDimension::D2,
                    format,
                    usage: wgpu::TextureUsages::RENDER_ATTACHMENT,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        let msaa = (self.sample_count > 1).then(|| texture("msaa colour", self.format));
        SizedTargets { size, msaa, depth: texture("depth", DEPTH_FORMAT) }
    }

    /// Draws `list` and the static lines as seen from `view_point` into `target` (a view of a texture
    /// of this renderer's format, `size` pixels) and submits the work.
    pub(crate) fn render(
        &mut self,
        target: &wgpu::TextureView,
        size: (u32, u32),
        view_point: &ViewPoint,
        list: &FrameDrawList,
    ) {
        let srgb = self.format.is_srgb();
        let globals = Globals {
            view_proj: view_point.view_projection.to_cols_array_2d(),
            eye: view_point.position.extend(1.0).to_array(),
            params: [if srgb { 1.0 } else { 0.0 }, 0.0, 0.0, 0.0],
        };
        self.queue.write_buffer(&self.globals, 0, bytemuck::bytes_of(&globals));

        let groups =
            [&list.spheres, &list.cylinders, &list.shadows, &list.translucent_spheres, &list.translucent_cylinders];
        let all: Vec<SolidInstance> = groups.iter().flat_map(|g| g.iter().copied()).collect();
        self.instances.write(&self.device, &self.queue, bytemuck::cast_slice(&all));
        let mut start = 0u32;
        let ranges = groups.map(|group| {
            let range = start..start + group.len() as u32;
            start = range.end;
            range
        });

        let to_target = |c: f32| if srgb { c.powf(2.2) } else { c } as f64;
        let bg = colors::BACKGROUND;
        let clear = wgpu::Color { r: to_target(bg[0]), g: to_target(bg[1]), b: to_target(bg[2]), a: 1.0 };
        let targets = match self.targets.take() {
            Some(t) if t.size == size => t,
            _ => self.create_targets(size),
        };
        let (view, resolve_target) = match &targets.msaa {
            Some(msaa) => (msaa, Some(target)),
            None => (target, None),
        };
        let mut encoder = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("frame") });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("scene"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(clear),
                        store: if resolve_target.is_some() { wgpu::StoreOp::Discard } else { wgpu::StoreOp::Store },
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &targets.depth,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Discard }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &self.bind_group, &[]);
            let p = &self.pipelines;
            let passes =
                [(&p.spheres, &self.sphere, ranges[0].clone()), (&p.cylinders, &self.cylinder, ranges[1].clone())];
            for (pipeline, mesh, range) in passes {
                draw_instanced(&mut pass, pipeline, mesh, &self.instances.buffer, range);
            }
            // Lines test against the solids' depth but do not write it.
            if self.line_vertex_count > 0 {
                pass.set_pipeline(&p.lines);
                pass.set_vertex_buffer(0, self.lines.buffer.slice(..));
                pass.draw(0..self.line_vertex_count, 0..1);
            }
            // Contact shadows blend over the floor and each other; then the translucent solids:
            // their nearest surface's depth first, then their colour where they are nearest.
            let passes = [
                (&p.translucent_cylinders, &self.cylinder, ranges[2].clone()),
                (&p.depth_spheres, &self.sphere, ranges[3].clone()),
                (&p.depth_cylinders, &self.cylinder, ranges[4].clone()),
                (&p.translucent_spheres, &self.sphere, ranges[3].clone()),
                (&p.translucent_cylinders, &self.cylinder, ranges[4].clone()),
            ];
            for (pipeline, mesh, range) in passes {
                draw_instanced(&mut pass, pipeline, mesh, &self.instances.buffer, range);
            }
        }
        self.queue.submit([encoder.finish()]);
        self.targets = Some(targets);
    }
}

fn draw_instanced(
    pass: &mut wgpu::RenderPass<'_>,
    pipeline: &wgpu::RenderPipeline,
    mesh: &GpuMesh,
    instances: &wgpu::Buffer,
    range: std::ops::Range<u32>,
) {
    if range.is_empty() {
        return;
    }
    pass.set_pipeline(pipeline);
    pass.set_vertex_buffer(0, mesh.vertices.slice(..));
    pass.set_vertex_buffer(1, instances.slice(..));
    pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint16);
    pass.draw_indexed(0..mesh.index_count, 0, range);
}
