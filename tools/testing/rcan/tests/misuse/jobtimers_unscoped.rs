// SPDX-License-Identifier: GPL-2.0
//! Misuse (issue 39, teardown duties: registrations forgotten at
//! `rmmod`): a module arms a job's timers (`JobTimers`, as CAN_BCM's
//! operations and a device's restart timer have) and forgets the job
//! (`mem::forget`, or a leaked owner). Its hrtimers stay queued after
//! `rmmod`: the next expiry runs freed module text in softirq (seen:
//! `rcan_bcm` changed to forget an armed job in init, `rmmod rcan_bcm`,
//! then an Oops when the timer fired). Now every job is on its module's
//! list and the exit kills what is left; `JobTimers::new` takes the
//! evidence that the module's exit is the glue's (`InScopedModule`: the
//! scope, a socket of a protocol it registered, a device it registered).
// expect: E0061 this function takes 2 arguments but 1 argument was supplied
#![forbid(unsafe_code)]

use crate::glue::jobtimer::{JobCallback, JobTimers};
use kernel::prelude::*;

pub(crate) fn arm_and_forget<H: JobCallback>(data: H::Data, at: u64) -> Result {
    let job = JobTimers::<H>::new(data)?;
    job.get().start(0, at);
    core::mem::forget(job);
    Ok(())
}
