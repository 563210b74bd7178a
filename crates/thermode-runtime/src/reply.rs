//! A one-shot slot for the loop's answer to one command: the loop thread fills it once, the requester takes it,
//! blocking (threads, tests) or as a future on any async executor (the network adapters). It depends on no async
//! runtime: waking uses the standard `Waker`, timing is the adapter's (see `Answer::wait_until` in `crate::command`).
//!
//! Filling allocates nothing (the slot is allocated by the requester), so the loop thread stays allocation-free.

use std::future::Future;
use std::pin::Pin;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::task::{Context, Poll, Waker};

/// The sender went away without filling the slot (the loop stopped).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("the control loop stopped before it answered")]
pub struct Closed;

#[derive(Debug)]
struct State<T> {
    value: Option<T>,
    sender_gone: bool,
    waker: Option<Waker>,
}

#[derive(Debug)]
struct Slot<T> {
    state: Mutex<State<T>>,
    filled: Condvar,
}

impl<T> Slot<T> {
    fn lock(&self) -> MutexGuard<'_, State<T>> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Stores `value` (or marks the sender gone) and wakes whoever waits.
    fn finish(&self, value: Option<T>) {
        let waker = {
            let mut state = self.lock();
            if state.sender_gone {
                return;
            }
            state.value = value;
            state.sender_gone = true;
            state.waker.take()
        };
        self.filled.notify_all();
        if let Some(waker) = waker {
            waker.wake();
        }
    }
}

/// A new slot: the loop's end and the requester's end.
pub fn slot<T>() -> (ReplySender<T>, ReplyReceiver<T>) {
    let slot = Arc::new(Slot {
        state: Mutex::new(State {
            value: None,
            sender_gone: false,
            waker: None,
        }),
        filled: Condvar::new(),
    });
    (ReplySender { slot: slot.clone() }, ReplyReceiver { slot })
}

/// The loop's end: filled once; dropping it unfilled tells the requester [`Closed`].
#[derive(Debug)]
pub struct ReplySender<T> {
    slot: Arc<Slot<T>>,
}

impl<T> ReplySender<T> {
    /// Fills the slot (a requester that already gave up simply never reads it).
    pub fn send(self, value: T) {
        self.slot.finish(Some(value));
    }
}

impl<T> Drop for ReplySender<T> {
    fn drop(&mut self) {
        self.slot.finish(None);
    }
}

/// The requester's end: a future, or [`ReplyReceiver::blocking_recv`].
#[derive(Debug)]
pub struct ReplyReceiver<T> {
    slot: Arc<Slot<T>>,
}

impl<T> ReplyReceiver<T> {
    /// Waits on this thread until the slot is filled (or the sender is gone).
    pub fn blocking_recv(self) -> Result<T, Closed> {
        let mut state = self.slot.lock();
        while !state.sender_gone {
            state = self.slot.filled.wait(state).unwrap_or_else(PoisonError::into_inner);
        }
        state.value.take().ok_or(Closed)
    }
}

impl<T> Future for ReplyReceiver<T> {
    type Output = Result<T, Closed>;

    fn poll(self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<Self::Output> {
        let mut state = self.slot.lock();
        if state.sender_gone {
            return Poll::Ready(state.value.take().ok_or(Closed));
        }
        if !state.waker.as_ref().is_some_and(|w| w.will_wake(cx.waker())) {
            state.waker = Some(cx.waker().clone());
        }
        Poll::Pending
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_filled_slot_gives_its_value_and_a_dropped_sender_gives_closed() {
        let (tx, rx) = slot();
        let waiter = std::thread::spawn(move || rx.blocking_recv());
        tx.send(7);
        assert_eq!(waiter.join().unwrap(), Ok(7));
        let (tx, rx) = slot::<u8>();
        drop(tx);
        assert_eq!(rx.blocking_recv(), Err(Closed));
    }

    #[test]
    fn a_polled_receiver_is_woken_when_the_slot_is_filled() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        use std::task::Wake;

        struct Count(AtomicUsize);
        impl Wake for Count {
            fn wake(self: Arc<Self>) {
                self.0.fetch_add(1, Ordering::SeqCst);
            }
        }
        let count = Arc::new(Count(AtomicUsize::new(0)));
        let waker = Waker::from(count.clone());
        let mut cx = Context::from_waker(&waker);
        let (tx, mut rx) = slot();
        assert!(Pin::new(&mut rx).poll(&mut cx).is_pending());
        tx.send("answer");
        assert_eq!(
            count.0.load(Ordering::SeqCst),
            1,
            "the filled slot wakes its poller once"
        );
        assert_eq!(Pin::new(&mut rx).poll(&mut cx), Poll::Ready(Ok("answer")));
    }
}
