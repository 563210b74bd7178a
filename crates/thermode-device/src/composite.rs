//! [`CompositeDevice`]: one display made of several devices (a five-finger glove on three two-channel TEC
//! controllers).
//!
//! The display's channels are the members' channels in the members' order: channel k of the composite is channel
//! `k - first` of the member whose range holds k. Every call goes to that member alone, so a member that fails or
//! falls silent fails only its own channels' reads and writes (the loop drives those channels off and their
//! envelopes fault), while the others go on; each member reconnects on its own (its own link health). A stop
//! ([`Device::all_off`]) reaches every member, each error counted but not stopping the others.
//!
//! The loop stays as it is: it sees one [`Device`]. Errors carry the member's own channel index (a
//! [`DeviceError::Cut`] or a link error names the member's channel, the loop knows which of its channels it asked).

use std::sync::Arc;

use thermode_safety::DriveCommand;

use crate::device::{Device, DevicePart, Measures, Reading, MAX_CHANNELS};
use crate::error::DeviceError;
use crate::link::LinkHealth;

/// A device of a [`CompositeDevice`].
struct Member {
    label: String,
    device: Box<dyn Device + Send>,
    first_channel: usize,
}

/// See the module documentation.
pub struct CompositeDevice {
    members: Vec<Member>,
    /// Per display channel: (member index, the member's channel).
    map: Vec<(usize, usize)>,
}

impl std::fmt::Debug for CompositeDevice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let labels: Vec<&str> = self.members.iter().map(|m| m.label.as_str()).collect();
        f.debug_struct("CompositeDevice")
            .field("members", &labels)
            .field("channels", &self.map.len())
            .finish()
    }
}

impl CompositeDevice {
    /// A display of `members` (each named by its label, e.g. its `--device` spelling), channels in their order. At
    /// least one member; every member has at least one channel, and all together 1 to [`MAX_CHANNELS`].
    pub fn new(members: Vec<(String, Box<dyn Device + Send>)>) -> Result<Self, DeviceError> {
        let total: usize = members.iter().map(|(_, d)| d.channel_count()).sum();
        let empty = members.iter().any(|(_, d)| d.channel_count() == 0);
        if members.is_empty() || empty || total > MAX_CHANNELS {
            return Err(DeviceError::ChannelCount {
                count: total,
                max: MAX_CHANNELS,
            });
        }
        let mut map = Vec::with_capacity(total);
        let mut built = Vec::with_capacity(members.len());
        for (index, (label, device)) in members.into_iter().enumerate() {
            let first_channel = map.len();
            map.extend((0..device.channel_count()).map(|local| (index, local)));
            built.push(Member {
                label,
                device,
                first_channel,
            });
        }
        Ok(CompositeDevice { members: built, map })
    }

    /// The member and its channel behind display channel `channel`.
    fn route(&mut self, channel: usize) -> Result<(&mut (dyn Device + Send), usize), DeviceError> {
        let count = self.map.len();
        let &(member, local) = self
            .map
            .get(channel)
            .ok_or(DeviceError::NoSuchChannel { channel, count })?;
        Ok((self.members[member].device.as_mut(), local))
    }
}

impl Device for CompositeDevice {
    fn channel_count(&self) -> usize {
        self.map.len()
    }

    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        let (device, local) = self.route(channel)?;
        device.apply(local, command)
    }

    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        let (device, local) = self.route(channel)?;
        device.read(local)
    }

    fn poll(&mut self, now_s: f64) {
        for member in &mut self.members {
            member.device.poll(now_s);
        }
    }

    /// Every member's own all-off (a serial display's `AllOff`, a MeCom device's every output disabled); a member
    /// that fails does not keep the others from stopping; the first error is returned.
    fn all_off(&mut self) -> Result<(), DeviceError> {
        let mut first = Ok(());
        for member in &mut self.members {
            if let Err(e) = member.device.all_off() {
                if first.is_ok() {
                    first = Err(e);
                }
            }
        }
        first
    }

    /// None: a composite has one link per member ([`Device::parts`]).
    fn link_health(&self) -> Option<Arc<LinkHealth>> {
        None
    }

    /// What every member measures (a quantity one member lacks is reported as unknown for all).
    fn measures(&self) -> Measures {
        self.members.iter().fold(Measures::ALL, |all, m| {
            let one = m.device.measures();
            Measures {
                drive_current: all.drive_current && one.drive_current,
                hot_side: all.hot_side && one.hot_side,
            }
        })
    }

    /// Each member's parts, its channels moved to the display's, named by the member's label unless the member
    /// names them itself (several addresses on one bus).
    fn parts(&self) -> Vec<DevicePart> {
        self.members
            .iter()
            .flat_map(|member| {
                member.device.parts().into_iter().map(move |part| DevicePart {
                    label: if part.label.is_empty() {
                        member.label.clone()
                    } else {
                        part.label
                    },
                    first_channel: member.first_channel + part.first_channel,
                    ..part
                })
            })
            .collect()
    }
}
