//! The special motions a soccer robot makes beside getting up and falling (which every biped
//! makes, and the robot crate names): what the platforms' catalogues call them, and whether
//! each moves the head.
//!
//! The soccer application orders them and the simulators run them (the built-in one,
//! rcssservermj's T1); both import this crate, so these names are the one vocabulary they
//! share (in logs and over TCP too: `{"kind":"kick","sequence":0}`). A NAO's motion files name
//! their own. Names never change meaning: a new motion gets a new name.

/// A motion's name and whether it moves the head.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Motion {
    pub name: &'static str,
    /// While the motion runs the head takes no head orders.
    pub head: bool,
}

/// Kicking the ball: the legs only, so the head keeps the ball in view.
pub const KICK: Motion = Motion { name: "kick", head: false };

/// The goalkeeper's dive (to a side, or a block): the whole robot.
pub const DIVE: Motion = Motion { name: "dive", head: true };
