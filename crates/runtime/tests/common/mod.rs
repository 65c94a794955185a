//! Small modules shared by the host tests.
#![allow(dead_code)]

use std::sync::{Arc, Mutex};

use strata_runtime::{Context, Input, Module, ModuleError, Output, Tap, TapRecord, Time};

/// Sends an increasing counter each cycle, optionally with noise from its own RNG.
pub struct Counter {
    pub out: Output<u64>,
    pub next: u64,
    pub noisy: bool,
    pub limit: Option<u64>,
}

impl Module for Counter {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        if self.limit.is_some_and(|limit| self.next >= limit) {
            return Ok(());
        }
        let value = if self.noisy {
            use rand::RngExt;
            self.next * 1000 + ctx.rng().random_range(0..1000u64)
        } else {
            self.next
        };
        self.next += 1;
        ctx.send(self.out, value);
        Ok(())
    }
}

/// What a recorder saw: (when it took it, value, stamp).
pub type Seen = Arc<Mutex<Vec<(Time, u64, Time)>>>;

/// Records every package it takes, with the time it took it.
pub struct Recorder {
    pub input: Input<u64>,
    pub seen: Seen,
    pub newest_only: bool,
}

impl Module for Recorder {
    fn cycle(&mut self, ctx: &mut Context<'_>) -> Result<(), ModuleError> {
        let now = ctx.now();
        let packages = if self.newest_only {
            ctx.latest(self.input).into_iter().collect()
        } else {
            ctx.drain(self.input)
        };
        let mut seen = self.seen.lock().unwrap_or_else(|e| e.into_inner());
        for p in packages {
            seen.push((now, p.value, p.stamp));
        }
        Ok(())
    }
}

/// One tapped package: (time, module, output, seq, stamp, json).
pub type Tapped = (Time, String, String, u64, Time, String);

/// Collects every package a host delivers.
#[derive(Default)]
pub struct Collect(pub Mutex<Vec<Tapped>>);

impl Tap for Collect {
    fn package(&self, r: &TapRecord<'_>) {
        let mut json = Vec::new();
        r.package.write_json(&mut json).expect("serializable");
        self.0.lock().unwrap_or_else(|e| e.into_inner()).push((
            r.time,
            r.sent_on.module_name.to_owned(),
            r.sent_on.output.to_owned(),
            r.package.seq(),
            r.package.stamp(),
            String::from_utf8(json).expect("utf-8"),
        ));
    }
}
