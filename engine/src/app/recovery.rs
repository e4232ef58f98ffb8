//! Surviving a lost device. A real GPU's driver resets a hung GPU (or a laptop switches GPUs)
//! and reports VK_ERROR_DEVICE_LOST; the engine's own watchdog (`Gpu::wait_fence`'s timeout)
//! calls a device that stops answering hung. Either way every object on it is gone, but nothing
//! the game knows is: the front ends (the window, `headless::Stage`) make a new device, the
//! renderer and the scene again from the pack they were showing, carry the state that lives on
//! the CPU over (`Renderer::carry_on_from`, `GpuScene::carry_on_from`, the overlay's history)
//! and draw the lost frame again. `LossPolicy` says when that is worth trying: not before the
//! first frame was shown (a device that cannot start will not start the second time either),
//! and not for a loss right after a recovery (a device that is lost again at once is broken).
//!
//! `ENGINE_INJECT_DEVICE_LOST` (`Gpu::submit_frame`) makes chosen frame submits report a loss,
//! so tests prove all this on lavapipe, which never loses a device.

use crate::anim::animated::AnimatedScene;
use crate::gpu::{DeviceLost, Gpu};
use crate::render::renderer::Renderer;
use crate::scene::GpuScene;
use anyhow::Result;
use ash::vk;

/// Decides which device losses a run survives.
#[derive(Debug, Default)]
pub struct LossPolicy {
    /// A frame has been shown since the start.
    started: bool,
    /// A recovery has been made and no frame has been shown since.
    recovering: bool,
    /// Devices made again so far.
    pub recoveries: u32,
}

impl LossPolicy {
    /// A frame was shown: start-up is over, and the last recovery (if any) held.
    pub fn frame_shown(&mut self) {
        self.started = true;
        self.recovering = false;
    }

    /// `e` ended a frame. Ok when it is a device loss to recover from (the caller then makes the
    /// device again and calls `recovered`); otherwise the error the run ends with: any other
    /// error as it is, a loss during start-up as it is (clear on its own), a loss right after a
    /// recovery with that said.
    pub fn survive(&mut self, e: anyhow::Error) -> Result<()> {
        if !e.is::<DeviceLost>() || !self.started {
            return Err(e);
        }
        if self.recovering {
            return Err(e.context("the GPU was lost again right after the device was made anew; giving up"));
        }
        Ok(())
    }

    /// The device was made again after a loss.
    pub fn recovered(&mut self) {
        self.recovering = true;
        self.recoveries += 1;
    }
}

/// A renderer writing `color_format` and `pack`'s scene and animated characters, on `gpu`; on an
/// error nothing made is left behind. Used at start-up and after a loss alike.
pub fn renderer_and_scene(gpu: &Gpu, pack: &pack::Pack, color_format: vk::Format, frames_in_flight: usize, shadow_map_size: u32) -> Result<(Renderer, GpuScene)> {
    let mut renderer = gpu.own(Renderer::new(gpu, color_format, frames_in_flight)?);
    renderer.set_shadow_map_size(gpu, shadow_map_size)?;
    let scene = gpu.own(GpuScene::upload(gpu, pack, renderer.layouts())?);
    renderer.animation = AnimatedScene::new(gpu, pack, &scene, frames_in_flight)?;
    Ok((renderer.keep(), scene.keep()))
}

/// What was made on the lost device goes: destroyed by `destroy` (the spec allows every
/// vkDestroy* after a loss; an injected loss left the device working), except on a hung device,
/// which may still be running work that uses it: then all of it, the device too, is left to the
/// process's exit.
pub fn retire<T>(gpu: Gpu, parts: T, destroy: impl FnOnce(&Gpu, T)) {
    if gpu.hung() {
        std::mem::forget(parts);
        std::mem::forget(gpu);
        return;
    }
    gpu.wait_idle();
    destroy(&gpu, parts);
    gpu.destroy_after_loss();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::DeviceLost;

    fn lost() -> anyhow::Error {
        DeviceLost("was lost (a driver reset or crash)", "while waiting for a frame, 60.0 s".into()).into()
    }

    #[test]
    fn a_loss_is_survived_after_start_up_once_until_a_frame_is_shown() {
        let mut p = LossPolicy::default();
        let e = p.survive(lost()).unwrap_err();
        assert!(e.is::<DeviceLost>(), "a loss before the first frame is the error itself");
        assert_eq!(format!("{e:#}"), "the GPU was lost (a driver reset or crash) (while waiting for a frame, 60.0 s)");
        p.frame_shown();
        p.survive(lost()).expect("a loss after start-up is survived");
        p.recovered();
        let e = p.survive(lost()).unwrap_err();
        assert!(e.is::<DeviceLost>());
        assert!(format!("{e:#}").starts_with("the GPU was lost again right after the device was made anew; giving up: the GPU was lost"), "{e:#}");
        p.frame_shown();
        p.survive(lost()).expect("a frame shown after the recovery: the next loss is survived again");
        assert_eq!(p.recoveries, 1);
        assert!(p.survive(anyhow::anyhow!("disk full")).is_err(), "other errors are not losses");
    }
}
