//! The LM3S6965's registers this firmware touches (system control, the UART pins' GPIO ports,
//! NVIC, SysTick), by address: no PAC needed.

use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicU32, Ordering};

/// Link UART rate \[bit/s\] (ignored by QEMU, which is not baud-limited).
pub const BAUD_LINK: u32 = 921_600;
/// Radar data UART rate \[bit/s\].
pub const BAUD_RADAR: u32 = 921_600;
/// IMU UART rate \[bit/s\] (the simulated MTi-1 sessions run at 921600; an MTi leaves the
/// factory at 115200).
pub const BAUD_IMU: u32 = 921_600;

const SYSCTL_RIS: usize = 0x400F_E050;
const SYSCTL_RCC: usize = 0x400F_E060;
const SYSCTL_RCGC1: usize = 0x400F_E104;
const SYSCTL_RCGC2: usize = 0x400F_E108;
/// GPIO ports A, D and G (the UARTs' pins) and their alternate-function and digital-enable
/// registers.
const GPIO_A: usize = 0x4000_4000;
const GPIO_D: usize = 0x4000_7000;
const GPIO_G: usize = 0x4002_6000;
const GPIO_AFSEL: usize = 0x420;
const GPIO_DEN: usize = 0x51C;
const SYST_CSR: usize = 0xE000_E010;
const SYST_RVR: usize = 0xE000_E014;
const SYST_CVR: usize = 0xE000_E018;
const NVIC_ISER0: usize = 0xE000_E100;
const NVIC_IPR: usize = 0xE000_E400;
const SCB_ICSR: usize = 0xE000_ED04;
const SCB_AIRCR: usize = 0xE000_ED0C;
const SCB_SHPR3: usize = 0xE000_ED20;

/// Error bits of a UART data-register read (framing, parity, break, overrun).
pub const DR_ERRORS: u32 = 0xF00;

#[inline(always)]
fn rd(a: usize) -> u32 {
    // SAFETY: `a` is one of this module's device register addresses.
    unsafe { read_volatile(a as *const u32) }
}

#[inline(always)]
fn wr(a: usize, v: u32) {
    // SAFETY: as above.
    unsafe { write_volatile(a as *mut u32, v) }
}

/// One UART (PL011 register layout).
#[derive(Clone, Copy)]
pub struct Uart {
    base: usize,
    irq: usize,
}

/// Hub link.
pub const UART0: Uart = Uart {
    base: 0x4000_C000,
    irq: 5,
};
/// Radar data port.
pub const UART1: Uart = Uart {
    base: 0x4000_D000,
    irq: 6,
};
/// IMU.
pub const UART2: Uart = Uart {
    base: 0x4000_E000,
    irq: 33,
};

const DR: usize = 0x00;
const FR: usize = 0x18;
const IBRD: usize = 0x24;
const FBRD: usize = 0x28;
const LCRH: usize = 0x2C;
const CTL: usize = 0x30;
const IFLS: usize = 0x34;
const IM: usize = 0x38;
const ICR: usize = 0x44;
const FR_RXFE: u32 = 1 << 4;
const FR_TXFF: u32 = 1 << 5;
/// Receive, receive-timeout and error interrupts.
const RX_INTS: u32 = (1 << 4) | (1 << 6) | (0xF << 7);

impl Uart {
    /// 8N1 with FIFOs at `baud` (50 MHz clock); receive interrupts at 1/8 full or timeout.
    pub fn init(self, baud: u32, rx_irq: bool) {
        wr(self.base + CTL, 0);
        // Divisor in 1/64 units: 50e6 * 4 / baud, rounded.
        let div = (50_000_000u32 * 4 + baud / 2) / baud;
        wr(self.base + IBRD, div >> 6);
        wr(self.base + FBRD, div & 0x3F);
        wr(self.base + LCRH, 0x70);
        wr(self.base + IFLS, 0);
        wr(self.base + ICR, 0x7FF);
        wr(self.base + IM, if rx_irq { RX_INTS } else { 0 });
        wr(self.base + CTL, (1 << 9) | (1 << 8) | 1);
        if rx_irq {
            // Same priority as SysTick: neither preempts the other.
            // SAFETY: byte-wide priority register of this IRQ.
            unsafe { write_volatile((NVIC_IPR + self.irq) as *mut u8, 0x80) };
        }
    }

    /// The next received word (data in bits 0-7, errors in 8-11), if the FIFO holds one.
    #[inline(always)]
    pub fn read_data(self) -> Option<u32> {
        if rd(self.base + FR) & FR_RXFE != 0 {
            None
        } else {
            Some(rd(self.base + DR))
        }
    }

    /// Acknowledges the receive interrupts.
    #[inline(always)]
    pub fn clear_interrupts(self) {
        wr(self.base + ICR, RX_INTS);
    }

    /// Writes a byte if the transmit FIFO has room.
    #[inline(always)]
    pub fn try_write(self, b: u8) -> bool {
        if rd(self.base + FR) & FR_TXFF != 0 {
            return false;
        }
        wr(self.base + DR, u32::from(b));
        true
    }
}

/// 50 MHz from the PLL (8 MHz crystal, 400 MHz VCO / 2 / SYSDIV 4), as the evaluation board's
/// examples do; enables the UART and GPIO clocks and routes the UART pins.
pub fn init_clock() {
    let mut rcc = rd(SYSCTL_RCC);
    // Bypass the PLL and stop the divider while changing it.
    rcc = (rcc | (1 << 11)) & !(1 << 22);
    wr(SYSCTL_RCC, rcc);
    // Main oscillator, 8 MHz crystal, PLL powered.
    rcc = (rcc & !((0xF << 6) | (0x3 << 4) | (1 << 13) | 1)) | (0xE << 6);
    // SYSDIV 3 (divide by 4) and use it.
    rcc = (rcc & !(0xF << 23)) | (3 << 23) | (1 << 22);
    wr(SYSCTL_RCC, rcc);
    // Wait for the PLL lock, bounded: never hang in the clock setup.
    let mut n = 0u32;
    while rd(SYSCTL_RIS) & (1 << 6) == 0 && n < 200_000 {
        n += 1;
    }
    wr(SYSCTL_RCC, rcc & !(1 << 11));
    wr(SYSCTL_RCGC1, rd(SYSCTL_RCGC1) | 0x7);
    // GPIO A, D, G.
    wr(
        SYSCTL_RCGC2,
        rd(SYSCTL_RCGC2) | (1 << 0) | (1 << 3) | (1 << 6),
    );
    // A few cycles for the peripheral clocks to start.
    cortex_m::asm::delay(16);
    // The UART pins: U0Rx/U0Tx PA0/PA1, U1Rx/U1Tx PD2/PD3, U2Rx/U2Tx PG0/PG1, as the alternate
    // (UART) function. QEMU does not route pins; a real board receives nothing without this.
    for (port, pins) in [(GPIO_A, 0x03), (GPIO_D, 0x0C), (GPIO_G, 0x03)] {
        wr(port + GPIO_AFSEL, rd(port + GPIO_AFSEL) | pins);
        wr(port + GPIO_DEN, rd(port + GPIO_DEN) | pins);
    }
}

static WRAPS: AtomicU32 = AtomicU32::new(0);
const RELOAD: u32 = 0x00FF_FFFF;

/// SysTick on the core clock, full 24-bit range, wrap interrupt at the UARTs' priority.
pub fn init_systick() {
    wr(SCB_SHPR3, (rd(SCB_SHPR3) & 0x00FF_FFFF) | (0x80 << 24));
    wr(SYST_RVR, RELOAD);
    wr(SYST_CVR, 0);
    wr(SYST_CSR, 0b111);
}

/// SysTick's wrap interrupt.
#[inline(always)]
pub fn systick_wrapped() {
    WRAPS.fetch_add(1, Ordering::Relaxed);
}

/// SysTick's current (down-counting) value.
#[inline(always)]
pub fn systick_val() -> u32 {
    rd(SYST_CVR)
}

/// Timer ticks since boot, from a context that SysTick cannot preempt (its own priority, or
/// interrupts off): a wrap that happened but is not yet counted shows as a pending SysTick.
#[inline(always)]
pub fn now_ticks_isr() -> u64 {
    let w = WRAPS.load(Ordering::Relaxed);
    let v = systick_val();
    if rd(SCB_ICSR) & (1 << 26) != 0 {
        // Wrapped, not counted yet: read again after the wrap for a consistent pair.
        let v = systick_val();
        (u64::from(w) + 1) << 24 | u64::from(RELOAD - v)
    } else {
        u64::from(w) << 24 | u64::from(RELOAD - v)
    }
}

/// Runs `f` with interrupts masked (the main loop's side of the stamp rings, the clock read).
pub fn critical<R>(f: impl FnOnce() -> R) -> R {
    cortex_m::interrupt::free(|_| f())
}

/// Timer ticks since boot, from the main loop.
pub fn now_ticks() -> u64 {
    critical(now_ticks_isr)
}

/// Enables the sensor UARTs' interrupts.
pub fn enable_irqs() {
    wr(NVIC_ISER0 + 4, 1 << (UART2.irq - 32));
    wr(NVIC_ISER0, 1 << UART1.irq);
}

/// Sleeps until an interrupt unless `work()` says there is something to do; checked with
/// interrupts masked so a byte that arrives in between still wakes the WFI.
pub fn sleep_unless_pending(work: impl Fn() -> bool) {
    cortex_m::interrupt::disable();
    if !work() {
        cortex_m::asm::wfi();
    }
    // SAFETY: interrupts were enabled before this function (the main loop runs with them on).
    unsafe { cortex_m::interrupt::enable() };
}

/// System reset.
pub fn reset() -> ! {
    wr(SCB_AIRCR, (0x05FA << 16) | (1 << 2));
    loop {
        cortex_m::asm::nop();
    }
}
