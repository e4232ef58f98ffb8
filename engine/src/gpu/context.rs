//! The Vulkan 1.3 instance, device, queue and memory allocator that everything else borrows.

use super::validation::{messenger_callback, ValidationLog};
use anyhow::{anyhow, bail, Context as _, Result};
use ash::vk;
use gpu_allocator::vulkan::{Allocator, AllocatorCreateDesc};
use std::ffi::{c_char, CStr};
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::path::PathBuf;
use std::time::Duration;
use super::pipeline_cache::DiskCache;

/// How long a wait for the GPU may take before the device is called hung, unless
/// ENGINE_GPU_TIMEOUT_S says otherwise: far above any frame (seconds on lavapipe under load),
/// far below forever. A real driver resets a hung GPU after about 2 s and reports
/// VK_ERROR_DEVICE_LOST; lavapipe never gives up on its own.
pub const DEFAULT_GPU_TIMEOUT: Duration = Duration::from_secs(60);

/// The device is hung (a wait for it timed out) or lost: no further work can be trusted to
/// finish. The `Gpu` stops waiting for it; its owner may make a new one (`gpu::recovery`).
#[derive(Debug, thiserror::Error)]
#[error("the GPU {0} ({1})")]
pub struct DeviceLost(pub &'static str, pub String);

/// How a device stopped working.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Loss {
    /// The driver reported VK_ERROR_DEVICE_LOST: its objects may still be destroyed (the spec
    /// allows every vkDestroy* after a loss), and waits return at once.
    Lost,
    /// A wait timed out: the device may still be running the work, so nothing it could be
    /// using is destroyed; it is left to the process's exit.
    Hung,
    /// `ENGINE_INJECT_DEVICE_LOST` made a submit report a loss; the device itself is fine.
    Injected,
}

impl Loss {
    const fn code(self) -> u8 {
        match self {
            Loss::Lost => 1,
            Loss::Hung => 2,
            Loss::Injected => 3,
        }
    }

    fn from_code(c: u8) -> Option<Loss> {
        [Loss::Lost, Loss::Hung, Loss::Injected].into_iter().find(|l| l.code() == c)
    }
}

/// Frame submits made by this process (`Gpu::submit_frame`), across devices: the counter the
/// fault injection counts in.
static FRAME_SUBMITS: AtomicU64 = AtomicU64::new(0);

/// The frame submits (counted from 0 over the process, `FRAME_SUBMITS`) that report a lost
/// device instead of running: `ENGINE_INJECT_DEVICE_LOST`, a comma-separated list. A test's way
/// to lose a device on a CPU implementation that never loses one.
fn injected_losses() -> Result<&'static [u64]> {
    static LIST: std::sync::OnceLock<std::result::Result<Vec<u64>, String>> = std::sync::OnceLock::new();
    let list = LIST.get_or_init(|| match std::env::var("ENGINE_INJECT_DEVICE_LOST") {
        Err(_) => Ok(Vec::new()),
        Ok(v) => v
            .split(',')
            .map(|n| n.trim().parse::<u64>())
            .collect::<std::result::Result<Vec<u64>, _>>()
            .map_err(|_| format!("ENGINE_INJECT_DEVICE_LOST={v:?} is not a comma-separated list of frame numbers")),
    });
    list.as_deref().map_err(|e| anyhow!("{e}"))
}

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// Which physical device to use. `Auto` prefers a real GPU and falls back to a CPU
/// implementation (lavapipe).
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub enum DevicePreference {
    #[default]
    Auto,
    Cpu,
    Gpu,
    /// The first device whose name contains this text (case-insensitive).
    Named(String),
}

impl DevicePreference {
    /// Parse `auto`, `cpu`, `gpu` or a name fragment (the `ENGINE_DEVICE` variable / `--device`).
    pub fn parse(s: &str) -> DevicePreference {
        match s.to_ascii_lowercase().as_str() {
            "" | "auto" => DevicePreference::Auto,
            "cpu" => DevicePreference::Cpu,
            "gpu" => DevicePreference::Gpu,
            other => DevicePreference::Named(other.to_string()),
        }
    }

    /// From the `ENGINE_DEVICE` environment variable, `Auto` when unset.
    pub fn from_env() -> DevicePreference {
        std::env::var("ENGINE_DEVICE").map(|s| DevicePreference::parse(&s)).unwrap_or_default()
    }
}

#[derive(Debug, Clone, Default)]
pub struct GpuOptions {
    /// Enable VK_LAYER_KHRONOS_validation and count its errors.
    pub validation: bool,
    pub device: DevicePreference,
    /// Instance extensions a window surface needs (from ash-window); empty when headless.
    pub surface_extensions: Vec<*const c_char>,
    /// Where the pipeline cache is kept between runs (`pipeline_cache`); None: in memory only.
    pub pipeline_cache: Option<PathBuf>,
}

impl GpuOptions {
    /// The pipeline cache file of the binaries: `ENGINE_PIPELINE_CACHE` (empty: none), else
    /// `build/pipeline-cache.bin` when run where `build/` exists (the repository), else none.
    pub fn default_pipeline_cache() -> Option<PathBuf> {
        match std::env::var("ENGINE_PIPELINE_CACHE") {
            Ok(p) if p.is_empty() => None,
            Ok(p) => Some(PathBuf::from(p)),
            Err(_) => std::path::Path::new("build").is_dir().then(|| PathBuf::from("build/pipeline-cache.bin")),
        }
    }

    /// Validation is on when asked for explicitly or when `ENGINE_VALIDATION=1` (tests set it).
    pub fn validation_from_env() -> bool {
        matches!(std::env::var("ENGINE_VALIDATION").as_deref(), Ok("1") | Ok("true"))
    }
}

/// Device capabilities queried at start-up rather than assumed.
#[derive(Debug, Clone)]
pub struct Capabilities {
    pub device_name: String,
    pub device_type: vk::PhysicalDeviceType,
    pub api_version: u32,
    pub timestamp_period_ns: f32,
    pub timestamps: bool,
    pub pipeline_statistics: bool,
    /// Fragment shaders may write storage buffers (the renderer's fragment counter needs it).
    pub fragment_atomics: bool,
    pub sampler_anisotropy: Option<f32>,
    pub depth_format: vk::Format,
    /// The sample count MSAA renders with: 4 where the device renders the HDR format and the
    /// depth format with 4 samples (lavapipe does), else 1 (MSAA unavailable).
    pub msaa_samples: vk::SampleCountFlags,
    /// Cube-map array views (`imageCubeArray`): the reflection probes are one such array.
    pub cube_arrays: bool,
}

pub struct Gpu {
    pub entry: ash::Entry,
    pub instance: ash::Instance,
    pub physical_device: vk::PhysicalDevice,
    pub device: ash::Device,
    pub queue: vk::Queue,
    pub queue_family: u32,
    pub caps: Capabilities,
    /// Shared (Arc) so the overlay's egui renderer allocates from the same heaps; every holder
    /// of a clone is destroyed before the `Gpu`, like any other object made from it.
    pub allocator: ManuallyDrop<Arc<Mutex<Allocator>>>,
    /// Pool for one-off transfer command buffers.
    upload_pool: vk::CommandPool,
    /// Every pipeline is created through this cache (kept on disk when the options name a file).
    pub pipeline_cache: vk::PipelineCache,
    disk_cache: DiskCache,
    debug: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    validation_log: Arc<ValidationLog>,
    pub swapchain_capable: bool,
    /// `wait_fence`'s limit, in nanoseconds.
    timeout_ns: AtomicU64,
    /// 0 while the device works, else the `Loss` code: set once a submit or a wait found it
    /// lost or hung.
    loss: AtomicU8,
    /// Allocations left before one is made to fail (0: none fails): `fail_allocation`.
    pub(super) allocation_fault: AtomicU64,
}

fn cstr_name(raw: &[c_char]) -> String {
    // SAFETY: Vulkan guarantees the fixed-size name arrays are NUL-terminated.
    unsafe { CStr::from_ptr(raw.as_ptr()) }.to_string_lossy().into_owned()
}

impl Gpu {
    pub fn new(opts: &GpuOptions) -> Result<Gpu> {
        Gpu::create(opts, Arc::new(ValidationLog::default()), gpu_timeout_from_env()?)
    }

    /// A new device made with `opts` to take over from this one after a loss: the validation
    /// messages of both are counted together, and the wait limit is this one's.
    pub fn successor(&self, opts: &GpuOptions) -> Result<Gpu> {
        Gpu::create(opts, self.validation_log.clone(), self.timeout())
    }

    fn create(opts: &GpuOptions, validation_log: Arc<ValidationLog>, timeout: Duration) -> Result<Gpu> {
        injected_losses()?;
        // SAFETY: loading the Vulkan loader library; failure is reported, not assumed away.
        let entry = unsafe { ash::Entry::load() }
            .context("cannot load the Vulkan loader (libvulkan.so.1); install libvulkan1 and mesa-vulkan-drivers (`make setup`)")?;

        let mut layers: Vec<*const c_char> = Vec::new();
        let mut extensions = opts.surface_extensions.clone();
        if opts.validation {
            let available = unsafe { entry.enumerate_instance_layer_properties()? };
            if !available.iter().any(|l| cstr_name(&l.layer_name) == VALIDATION_LAYER.to_str().unwrap()) {
                bail!("validation was requested but VK_LAYER_KHRONOS_validation is not installed (Debian package vulkan-validationlayers)");
            }
            layers.push(VALIDATION_LAYER.as_ptr());
            extensions.push(ash::ext::debug_utils::NAME.as_ptr());
        }

        let app = vk::ApplicationInfo::default()
            .application_name(c"engine")
            .engine_name(c"engine")
            .api_version(vk::API_VERSION_1_3);
        let mut messenger_info = vk::DebugUtilsMessengerCreateInfoEXT::default()
            .message_severity(
                vk::DebugUtilsMessageSeverityFlagsEXT::ERROR | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING,
            )
            .message_type(
                vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                    | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                    | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
            )
            .pfn_user_callback(Some(messenger_callback))
            .user_data(Arc::as_ptr(&validation_log) as *mut _);
        let mut instance_info =
            vk::InstanceCreateInfo::default().application_info(&app).enabled_layer_names(&layers).enabled_extension_names(&extensions);
        if opts.validation {
            // Also catch messages from vkCreateInstance/vkDestroyInstance themselves.
            instance_info = instance_info.push_next(&mut messenger_info);
        }
        let instance = unsafe { entry.create_instance(&instance_info, None) }
            .context("vkCreateInstance failed (is a Vulkan 1.3 driver installed?)")?;
        let debug = if opts.validation {
            let du = ash::ext::debug_utils::Instance::new(&entry, &instance);
            let m = unsafe { du.create_debug_utils_messenger(&messenger_info, None)? };
            Some((du, m))
        } else {
            None
        };

        let (physical_device, queue_family) = match pick_device(&instance, &opts.device) {
            Ok(p) => p,
            Err(e) => {
                unsafe {
                    if let Some((du, m)) = &debug {
                        du.destroy_debug_utils_messenger(*m, None);
                    }
                    instance.destroy_instance(None);
                }
                return Err(e);
            }
        };
        let props = unsafe { instance.get_physical_device_properties(physical_device) };
        let features = unsafe { instance.get_physical_device_features(physical_device) };
        let device_exts = unsafe { instance.enumerate_device_extension_properties(physical_device)? };
        let swapchain_capable =
            device_exts.iter().any(|e| cstr_name(&e.extension_name) == ash::khr::swapchain::NAME.to_str().unwrap());
        let want_swapchain = !opts.surface_extensions.is_empty() && swapchain_capable;

        let queue_props = unsafe { instance.get_physical_device_queue_family_properties(physical_device) };
        let caps = Capabilities {
            device_name: cstr_name(&props.device_name),
            device_type: props.device_type,
            api_version: props.api_version,
            timestamp_period_ns: props.limits.timestamp_period,
            timestamps: queue_props[queue_family as usize].timestamp_valid_bits > 0,
            pipeline_statistics: features.pipeline_statistics_query == vk::TRUE,
            fragment_atomics: features.fragment_stores_and_atomics == vk::TRUE,
            sampler_anisotropy: (features.sampler_anisotropy == vk::TRUE).then_some(props.limits.max_sampler_anisotropy),
            depth_format: pick_depth_format(&instance, physical_device)?,
            msaa_samples: if props.limits.framebuffer_color_sample_counts.contains(vk::SampleCountFlags::TYPE_4)
                && props.limits.framebuffer_depth_sample_counts.contains(vk::SampleCountFlags::TYPE_4)
            {
                vk::SampleCountFlags::TYPE_4
            } else {
                vk::SampleCountFlags::TYPE_1
            },
            cube_arrays: features.image_cube_array == vk::TRUE,
        };

        let priorities = [1.0f32];
        let queue_info = [vk::DeviceQueueCreateInfo::default().queue_family_index(queue_family).queue_priorities(&priorities)];
        let enabled = vk::PhysicalDeviceFeatures::default()
            .pipeline_statistics_query(caps.pipeline_statistics)
            .fragment_stores_and_atomics(caps.fragment_atomics)
            .sampler_anisotropy(caps.sampler_anisotropy.is_some())
            .image_cube_array(caps.cube_arrays);
        // maintenance4 (required of every 1.3 device): glslc's Vulkan 1.3 compute shaders declare
        // their workgroup size with LocalSizeId, which needs it.
        let mut v13 = vk::PhysicalDeviceVulkan13Features::default().dynamic_rendering(true).synchronization2(true).maintenance4(true);
        let mut v12 = vk::PhysicalDeviceVulkan12Features::default().host_query_reset(true);
        let dev_exts: Vec<*const c_char> =
            if want_swapchain { vec![ash::khr::swapchain::NAME.as_ptr()] } else { vec![] };
        let device_info = vk::DeviceCreateInfo::default()
            .queue_create_infos(&queue_info)
            .enabled_features(&enabled)
            .enabled_extension_names(&dev_exts)
            .push_next(&mut v13)
            .push_next(&mut v12);
        let device = unsafe { instance.create_device(physical_device, &device_info, None) }
            .with_context(|| format!("vkCreateDevice failed on {}", caps.device_name))?;
        let queue = unsafe { device.get_device_queue(queue_family, 0) };

        let allocator = Allocator::new(&AllocatorCreateDesc {
            instance: instance.clone(),
            device: device.clone(),
            physical_device,
            debug_settings: Default::default(),
            buffer_device_address: false,
            allocation_sizes: Default::default(),
        })
        .map_err(|e| anyhow!("gpu-allocator: {e}"))?;
        let disk_cache = DiskCache::open(&device, opts.pipeline_cache.as_deref())?;
        let upload_pool = unsafe {
            device.create_command_pool(
                &vk::CommandPoolCreateInfo::default()
                    .queue_family_index(queue_family)
                    .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                None,
            )?
        };

        Ok(Gpu {
            entry,
            instance,
            physical_device,
            device,
            queue,
            queue_family,
            caps,
            allocator: ManuallyDrop::new(Arc::new(Mutex::new(allocator))),
            upload_pool,
            pipeline_cache: disk_cache.cache,
            disk_cache,
            debug,
            validation_log,
            swapchain_capable: want_swapchain,
            timeout_ns: AtomicU64::new(timeout.as_nanos().min(u64::MAX as u128) as u64),
            loss: AtomicU8::new(0),
            allocation_fault: AtomicU64::new(0),
        })
    }

    /// Waits for `fence`, signalled when `what` is done. A device that does not get there within
    /// the timeout, or reports itself lost, is an error (`DeviceLost`) instead of a wait forever,
    /// and the `Gpu` is marked lost.
    pub fn wait_fence(&self, fence: vk::Fence, what: &str) -> Result<()> {
        self.alive(what)?;
        let (why, loss) = match unsafe { self.device.wait_for_fences(&[fence], true, self.timeout_ns.load(Ordering::Relaxed)) } {
            Ok(()) => return Ok(()),
            Err(vk::Result::TIMEOUT) => ("did not finish in time: it is hung", Loss::Hung),
            Err(vk::Result::ERROR_DEVICE_LOST) => ("was lost (a driver reset or crash)", Loss::Lost),
            Err(e) => return Err(anyhow!("waiting for {what}: {e}")),
        };
        self.loss.store(loss.code(), Ordering::Relaxed);
        Err(DeviceLost(why, format!("while waiting for {what}, {:.1} s", self.timeout().as_secs_f64())).into())
    }

    /// Submits a frame's command buffers (`vkQueueSubmit2`), signalling `fence`. A device that
    /// reports itself lost is `DeviceLost`; so is a submit `ENGINE_INJECT_DEVICE_LOST` names,
    /// which then submits nothing (the work recorded for it is never run).
    pub fn submit_frame(&self, submits: &[vk::SubmitInfo2], fence: vk::Fence) -> Result<()> {
        self.alive("a frame")?;
        let n = FRAME_SUBMITS.fetch_add(1, Ordering::Relaxed);
        if injected_losses()?.contains(&n) {
            self.loss.store(Loss::Injected.code(), Ordering::Relaxed);
            return Err(DeviceLost("was lost (injected by ENGINE_INJECT_DEVICE_LOST)", format!("at frame submit {n}")).into());
        }
        match unsafe { self.device.queue_submit2(self.queue, submits, fence) } {
            Ok(()) => Ok(()),
            Err(vk::Result::ERROR_DEVICE_LOST) => {
                self.loss.store(Loss::Lost.code(), Ordering::Relaxed);
                Err(DeviceLost("was lost (a driver reset or crash)", format!("at frame submit {n}")).into())
            }
            Err(e) => Err(anyhow!("submitting a frame: {e}")),
        }
    }

    /// Destroys a device that was lost (not hung) once every object made on it was destroyed
    /// (`app::recovery::retire`); a working one is simply dropped.
    pub fn destroy_after_loss(self) {
        if !self.hung() {
            self.loss.store(0, Ordering::Relaxed);
        }
        drop(self);
    }

    /// How the device stopped working, if it did.
    pub fn loss(&self) -> Option<Loss> {
        Loss::from_code(self.loss.load(Ordering::Relaxed))
    }

    /// Whether its objects must be left alone: a hung device may still be using them.
    pub fn hung(&self) -> bool {
        self.loss() == Some(Loss::Hung)
    }

    /// The limit of `wait_fence`.
    pub fn timeout(&self) -> Duration {
        Duration::from_nanos(self.timeout_ns.load(Ordering::Relaxed))
    }

    pub fn set_timeout(&self, limit: Duration) {
        self.timeout_ns.store(limit.as_nanos().min(u64::MAX as u128) as u64, Ordering::Relaxed);
    }

    /// An error once the device is hung or lost: callers check before recording `what`, since
    /// the command buffers of the hung work are still pending.
    pub fn alive(&self, what: &str) -> Result<()> {
        match self.is_lost() {
            true => Err(DeviceLost("was lost before", format!("{what} was not started")).into()),
            false => Ok(()),
        }
    }

    /// Whether a submit or a wait found the device hung or lost.
    pub fn is_lost(&self) -> bool {
        self.loss().is_some()
    }

    /// Everything the validation layer has reported so far (empty when validation is off).
    pub fn validation(&self) -> &ValidationLog {
        &self.validation_log
    }

    /// The validation log, to read after the `Gpu` is gone (its destruction is validated too).
    pub fn validation_log(&self) -> Arc<ValidationLog> {
        self.validation_log.clone()
    }

    pub fn validation_enabled(&self) -> bool {
        self.debug.is_some()
    }

    /// Record and run a one-off command buffer, waiting for it to finish. For uploads and
    /// read-backs at load time, not for per-frame work.
    pub fn one_shot<R>(&self, record: impl FnOnce(vk::CommandBuffer) -> R) -> Result<R> {
        let d = &self.device;
        unsafe {
            let cb = d.allocate_command_buffers(
                &vk::CommandBufferAllocateInfo::default()
                    .command_pool(self.upload_pool)
                    .level(vk::CommandBufferLevel::PRIMARY)
                    .command_buffer_count(1),
            )?[0];
            d.begin_command_buffer(cb, &vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT))?;
            let r = record(cb);
            d.end_command_buffer(cb)?;
            let fence = d.create_fence(&vk::FenceCreateInfo::default(), None)?;
            let cbs = [vk::CommandBufferSubmitInfo::default().command_buffer(cb)];
            let submit = [vk::SubmitInfo2::default().command_buffer_infos(&cbs)];
            let res = match d.queue_submit2(self.queue, &submit, fence) {
                Ok(()) => self.wait_fence(fence, "an upload"),
                Err(e) => Err(e.into()),
            };
            if !self.hung() {
                d.destroy_fence(fence, None);
                d.free_command_buffers(self.upload_pool, &[cb]);
            }
            res?;
            Ok(r)
        }
    }

    /// Waits for all the device's work (not at all once it is hung: that would never return; a
    /// lost device returns at once).
    pub fn wait_idle(&self) {
        if !self.hung() {
            unsafe {
                let _ = self.device.device_wait_idle();
            }
        }
    }
}

impl Drop for Gpu {
    fn drop(&mut self) {
        if self.is_lost() {
            // Its owner may not have destroyed what it made on it (an error ends the run on the
            // way out), and a hung device would be waited for forever (or have memory freed
            // under it): leave everything to the process's exit. A recovery that did destroy
            // everything lets it go with `destroy_after_loss`.
            return;
        }
        unsafe {
            let _ = self.device.device_wait_idle();
            self.device.destroy_command_pool(self.upload_pool, None);
            self.disk_cache.close(&self.device);
            // The allocator frees its memory blocks on drop, which needs the device alive: a clone
            // still held here (an overlay not destroyed) would free them after the device.
            if !std::thread::panicking() {
                assert_eq!(Arc::strong_count(&self.allocator), 1, "an allocator clone outlives the Gpu");
            }
            ManuallyDrop::drop(&mut self.allocator);
            self.device.destroy_device(None);
            if let Some((du, m)) = self.debug.take() {
                du.destroy_debug_utils_messenger(m, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

/// ENGINE_GPU_TIMEOUT_S (seconds, > 0) or the default.
fn gpu_timeout_from_env() -> Result<Duration> {
    match std::env::var("ENGINE_GPU_TIMEOUT_S") {
        Err(_) => Ok(DEFAULT_GPU_TIMEOUT),
        Ok(v) => v
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|s| *s > 0.0 && s.is_finite())
            .map(Duration::from_secs_f64)
            .ok_or_else(|| anyhow!("ENGINE_GPU_TIMEOUT_S={v:?} is not a positive number of seconds")),
    }
}

/// Choose a physical device with Vulkan 1.3, dynamic rendering and a graphics+compute queue.
fn pick_device(instance: &ash::Instance, pref: &DevicePreference) -> Result<(vk::PhysicalDevice, u32)> {
    let devices = unsafe { instance.enumerate_physical_devices()? };
    let mut candidates = Vec::new();
    let mut rejected = Vec::new();
    for pd in devices {
        let props = unsafe { instance.get_physical_device_properties(pd) };
        let name = cstr_name(&props.device_name);
        if props.api_version < vk::API_VERSION_1_3 {
            rejected.push(format!("{name}: Vulkan {}.{} < 1.3", vk::api_version_major(props.api_version), vk::api_version_minor(props.api_version)));
            continue;
        }
        let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
        let mut f2 = vk::PhysicalDeviceFeatures2::default().push_next(&mut f13);
        unsafe { instance.get_physical_device_features2(pd, &mut f2) };
        if f13.dynamic_rendering != vk::TRUE || f13.synchronization2 != vk::TRUE {
            rejected.push(format!("{name}: no dynamic rendering / synchronization2"));
            continue;
        }
        let families = unsafe { instance.get_physical_device_queue_family_properties(pd) };
        let Some(qf) = families.iter().position(|q| {
            q.queue_flags.contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE)
        }) else {
            rejected.push(format!("{name}: no graphics+compute queue"));
            continue;
        };
        let is_cpu = props.device_type == vk::PhysicalDeviceType::CPU;
        let matches = match pref {
            DevicePreference::Auto => true,
            DevicePreference::Cpu => is_cpu,
            DevicePreference::Gpu => !is_cpu,
            DevicePreference::Named(n) => name.to_ascii_lowercase().contains(n),
        };
        if !matches {
            rejected.push(format!("{name}: not selected by device preference {pref:?}"));
            continue;
        }
        let rank = match props.device_type {
            vk::PhysicalDeviceType::DISCRETE_GPU => 0,
            vk::PhysicalDeviceType::INTEGRATED_GPU => 1,
            vk::PhysicalDeviceType::VIRTUAL_GPU => 2,
            vk::PhysicalDeviceType::CPU => 3,
            _ => 4,
        };
        candidates.push((rank, pd, qf as u32));
    }
    candidates.sort_by_key(|c| c.0);
    candidates.first().map(|c| (c.1, c.2)).ok_or_else(|| {
        anyhow!(
            "no usable Vulkan device (preference {pref:?}); considered: [{}]. Install mesa-vulkan-drivers for lavapipe.",
            rejected.join("; ")
        )
    })
}

fn pick_depth_format(instance: &ash::Instance, pd: vk::PhysicalDevice) -> Result<vk::Format> {
    // D32_SFLOAT first: reversed-Z wants float depth.
    for f in [vk::Format::D32_SFLOAT, vk::Format::D32_SFLOAT_S8_UINT, vk::Format::D24_UNORM_S8_UINT] {
        let p = unsafe { instance.get_physical_device_format_properties(pd, f) };
        if p.optimal_tiling_features.contains(vk::FormatFeatureFlags::DEPTH_STENCIL_ATTACHMENT) {
            return Ok(f);
        }
    }
    bail!("the device has no usable depth format")
}
